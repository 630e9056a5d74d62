"""``ermrl compare LABEL=SUMMARY.json ...``: variants (test phases or ``ermrl train`` runs) compared seed by seed,
as a Markdown table, P(A > B) and paired differences, and optionally one figure of their learning curves."""

from __future__ import annotations

import sys

from ermrl.cli import common, options
from ermrl.errors import ConfigError


def add_parser(sub, formatter) -> None:
    from ermrl.analysis import variants

    p = sub.add_parser("compare", help="variants' test phases or train runs on the same seeds: table, P(A > B), "
                                       "paired differences, curves",
                       description="Read each variant's summary.json (a test phase's, or an `ermrl train` run's; "
                                   "several train runs on other seeds join into one variant with ','), and print a "
                                   "Markdown table: each variant's ER-MRL row (n, mean ± std, IQM [95%% CI], AUC over "
                                   "the first 300k steps), then the first test phase's PPO rows; then for each "
                                   "--compare A B, P(A > B) with its 95%% CI (rliable) and the paired difference "
                                   "A − B over the shared seeds (BCa CI, Wilcoxon p) of the final score and, where "
                                   "both have a curves.csv beside their summary, of the AUC over the first 300k "
                                   "steps. --figure draws every variant's "
                                   "learning curve and the PPO curves, from the curves.csv beside each summary.",
                       formatter_class=formatter)
    p.add_argument("variants", nargs="+", type=_variant, metavar="LABEL=SUMMARY.json",
                   help="a variant's name and its test phase's summary.json, or `ermrl train` runs' summaries "
                        "joined by ',' (their seeds pooled)")
    options.sets(p.add_argument("--compare", nargs=2, action="append", default=[], metavar=("A", "B"),
                                help="print P(A > B) and the paired difference A − B (repeatable); A or B: a "
                                     "variant's label or a PPO row's model name, e.g. 'PPO (full observation)'"),
                 "comparisons", variants.table)
    p.add_argument("--figure", type=options.path, default=None, metavar="PATH.png",
                   help="also draw every variant's ER-MRL learning curve and the PPO curves there")
    p.add_argument("--title", default="reservoir variants, the same seeds",
                   help="the figure's title, after the env id (e.g. 'Φ* at two learning rates')")
    options.add_config_option(p)


def _variant(text: str):
    import argparse

    from ermrl.analysis.variants import parse_variant

    try:
        return parse_variant(text)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def cmd_compare(args) -> int:
    from ermrl import storage
    from ermrl.analysis import variants as v

    labels = [label for label, _ in args.variants]
    twice = next((x for x in labels if labels.count(x) > 1), None)
    if twice is not None:
        raise ConfigError(f"two variants are named {twice!r}; name each once")
    for _, paths in args.variants:
        for path in paths:
            if not path.is_file():
                raise ConfigError(f"{path} is not a file; give a test phase's or an `ermrl train` run's summary.json")
    figure = None if args.figure is None else storage.check_file(args.figure.with_suffix(".png"), "--figure")
    variants = dict(args.variants)
    try:
        text = v.table(variants, [tuple(c) for c in args.compare])
        drawn = v.curves(variants) if figure is not None else None  # read before anything is written
        title = f"{v.env_id(args.variants[0][1][0])}: {args.title}"
    except ConfigError:
        raise  # the library's message, whose parameters the command shows as its flags
    except (OSError, ValueError) as e:
        raise ConfigError(common.one_line(e)) from None
    sys.stdout.write(text)
    if drawn is not None:
        from ermrl.analysis.plots import learning_curves

        learning_curves(drawn, title, figure)
    return 0

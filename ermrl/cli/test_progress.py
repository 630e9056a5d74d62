"""``ermrl test-progress OUT``: the scores so far of an unfinished test phase, from the models it keeps in
``OUT.partial/`` and the snapshot of the one in training."""

from __future__ import annotations

import sys

from ermrl.cli import common, options
from ermrl.errors import ConfigError


def add_parser(sub, formatter) -> None:
    p = sub.add_parser("test-progress", help="the scores so far of an unfinished test phase (OUT.partial/)",
                       description="A test phase writes its summary only at the end; until then each finished model "
                                   "(or group of agents, --agents-per-run) waits in OUT.partial/, and the model in "
                                   "training keeps a snapshot there. Print one Markdown row per kept model (its "
                                   "groups joined: agents kept, seeds, final mean ± std, IQM [95%% CI], per-seed "
                                   "scores) and one per model in training (steps done, each agent's mean return over "
                                   "its last 10 episodes so far).", formatter_class=formatter)
    p.add_argument("partial", type=options.path, metavar="OUT[.partial]",
                   help="the test phase's folder (e.g. runs/experiments/EXP-SCALE/STUDY/test) or its .partial "
                        "folder beside it")
    options.add_config_option(p)


def cmd_test_progress(args) -> int:
    from ermrl.analysis import test_progress

    try:
        text = test_progress.table(test_progress.partial_folder(args.partial))
    except (OSError, ValueError) as e:
        raise ConfigError(common.one_line(e)) from None
    sys.stdout.write(text)
    return 0

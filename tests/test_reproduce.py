"""`ermrl reproduce`: the paper's reproduction steps as data (ermrl/experiments/reproduction/), listed, printed,
picked by name or claim, and run; the test phases' files kept between runs/experiments/ and docs/data/."""

import shutil
from pathlib import Path

import pytest

from ermrl.experiments.reproduction import catalog, folders
from ermrl.experiments.reproduction.actions import Exists, PhiFlags, Run, Step, compare

from cli_runs import ermrl

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "docs" / "data"


def test_list_shows_every_step_in_order_with_its_claims():
    r = ermrl("reproduce", "--list")
    assert r.returncode == 0, r.stderr
    rows = r.stdout.splitlines()
    assert [row.split()[0] for row in rows] == list(catalog.ORDER)
    h2 = next(row for row in rows if row.startswith("h2_converged "))
    assert h2.split()[1] == "C7" and "C7 at --scale converged" in h2
    assert next(row for row in rows if row.startswith("lunarlander ")).split()[1] == "C1,C2,C3"


def test_every_claim_has_a_step_and_every_step_a_description():
    steps = catalog.steps()
    assert set(steps) == set(catalog.ORDER)
    for claim in catalog.CLAIMS:
        assert any(claim in s.claims for s in steps.values()), claim
    for s in steps.values():
        assert s.actions and s.description and "\n" not in s.description
        assert set(s.claims) <= set(catalog.CLAIMS), s.name


def test_a_claim_picks_its_steps_in_order_and_a_step_name_itself():
    names = lambda words: [s.name for s in catalog.select(words)]
    assert names(["C7"]) == ["h2", "h2_converged", "h2_converged_interim"]
    assert names(["C3"]) == ["lunarlander", "lunarlander_1res", "c3_converged"]
    assert names(["c8"]) == ["c8"]  # a step's name, lower case; C8 is the claim
    assert names(["C8"]) == ["c8", "c8_converged"]
    assert names(["C10"]) == ["h3", "h3_converged", "h3_converged_interim"]
    assert names(["pendulum", "h2", "pendulum"]) == ["pendulum", "h2"]  # the order given, each once
    assert names(["C9", "fft"]) == ["fft", "fft_early"]
    assert names([]) == list(catalog.ORDER)


def test_dry_run_prints_the_exact_commands():
    r = ermrl("reproduce", "--dry-run", "h2_converged")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("== h2_converged (C7): C7 at --scale converged")
    run = ("ermrl experiment run locomotion --scale converged --storage docs/data/locomotion-converged/studies.log "
           "--out runs/experiments/locomotion-converged --baseline-store docs/data/baseline-models --only {}-2res "
           "--test-seeds 10 --test-timesteps 1000000")
    assert [x for x in lines if x.startswith("ermrl experiment")] == [run.format(s)
                                                                       for s in ("halfcheetah", "swimmer", "ant")]
    assert lines[1:5] == ["# restore docs/data/locomotion-converged -> runs/experiments/locomotion-converged",
                          run.format("halfcheetah"),
                          "# collect runs/experiments/locomotion-converged -> docs/data/locomotion-converged",
                          "# stash runs/experiments/locomotion-converged -> docs/data/locomotion-converged (also when "
                          "the run stops)"]
    # each finished study is compared with PPO and the small study's Φ* before the next one starts
    d = "docs/data/locomotion-converged/halfcheetah-2res"
    assert lines[5] == (
        f"ermrl compare 'converged study={d}/test/summary.json' 'small study=docs/data/locomotion-small/halfcheetah-2res/"
        "test/summary.json' --compare 'converged study' 'PPO (same observation)' --compare 'converged study' 'small "
        f"study' --title 'Φ* of the converged and the small study' --figure {d}/comparison.png | tee "
        f"{d}/comparison.md")
    assert len(lines) == 16


def test_the_converged_generalization_groups_are_compared_on_their_held_out_envs():
    r = ermrl("reproduce", "--dry-run", "h3_converged")
    assert r.returncode == 0, r.stderr
    compares = [x for x in r.stdout.splitlines() if x.startswith("ermrl compare")]
    d, small = "docs/data/generalization-morphology-converged", "docs/data/generalization-morphology-small"
    assert [x.split("'")[1] for x in compares] == [
        f"converged study={d}/to-{t}/test-{env}/summary.json"
        for t, env in (("ant", "Ant-v5"), ("halfcheetah", "HalfCheetah-v5"), ("swimmer", "Swimmer-v5"))]
    assert all(x.split("'")[3].startswith(f"small study={small}/") and x.endswith("/comparison.md") for x in compares)


def test_an_interim_generalization_test_runs_on_the_held_out_env():
    r = ermrl("reproduce", "--dry-run", "h3_converged_interim")
    assert r.returncode == 0, r.stderr
    d = "docs/data/generalization-morphology-converged/to-ant-gen21"
    where = f"--study generalization-morphology-converged-to-ant --storage {d}/studies.log"
    assert r.stdout.splitlines()[1:4] == [
        f"[ -e {d}/studies.log ] || python paper/study_so_far.py --study generalization-morphology-converged-to-ant "
        f"--storage journal:docs/data/generalization-morphology-converged/studies.log --generation 21 --to "
        f"journal:{d}/studies.log",
        f"ermrl select {where} --out runs/generalization-morphology-converged-to-ant-gen21 --top 5 --seeds 5 --quiet",
        f"[ -e {d}/test-Ant-v5/summary.json ] || ermrl test {where} --out {d} --env Ant-v5 --seeds 10 --timesteps "
        "1000000 --auc-steps 300000 --baseline-store docs/data/baseline-models --no-save-agents --quiet"]
    assert "small study=docs/data/generalization-morphology-small/to-ant/test-Ant-v5/summary.json" in r.stdout


def test_dry_run_shows_skip_conditions_values_known_later_and_output_files():
    r = ermrl("reproduce", "--dry-run", "pendulum_lr1e4")
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert "ermrl select --study pendulum-lr1e-4 --storage docs/data/pendulum-lr1e-4/studies.log --out " \
           "runs/pendulum-lr1e-4 --top 5 --seeds 5 --quiet" in lines
    assert "[ -e docs/data/pendulum-lr1e-4/ermrl/summary.json ] || ermrl train --env PendulumNoVel-v1 --units 100 " \
           "'<Φ* of pendulum-lr1e-4 in docs/data/pendulum-lr1e-4/studies.log>' --seeds 10 --first-seed 1000 " \
           "--timesteps 1000000 --learning-rate 1e-4 --no-save-agents --quiet --out docs/data/pendulum-lr1e-4/ermrl" in lines
    assert lines[-1] == "ermrl compare 'Φ* evolved at 1e-4=docs/data/pendulum-lr1e-4/ermrl/summary.json' | tee " \
                        "docs/data/pendulum-lr1e-4/summary.md"


@pytest.mark.parametrize("word", ["nope", "c7", "C18"])
def test_an_unknown_step_or_claim_is_one_line_and_exit_2(word):
    r = ermrl("reproduce", "--dry-run", "h2", word)
    assert (r.returncode, r.stdout) == (2, "")
    assert r.stderr == (f"ermrl reproduce: error: unknown step or claim {word!r}; steps: {' '.join(catalog.ORDER)}; "
                        f"claims: {' '.join(catalog.CLAIMS)}\n")


def test_a_root_without_docs_data_is_refused(tmp_path):
    r = ermrl("reproduce", "h2", "--root", tmp_path)
    assert (r.returncode, r.stdout) == (2, "")
    assert r.stderr == (f"ermrl reproduce: error: {tmp_path} is not the repository's root (it has no docs/data/); "
                        "run from a checkout of ermrl, or give --root\n")


def test_a_step_runs_end_to_end_on_committed_data(tmp_path):
    """Step observed_units_lr3e4 in a copy of its committed inputs: its training is done (summary.json there), so
    it is skipped (and its Φ* never read); `ermrl compare` writes the committed table again, byte for byte, and the
    figure."""
    d = "docs/data/observed-units-small/1000-of-1000"
    for run in ("test", "ermrl-lr3e-4"):
        (tmp_path / d / run).mkdir(parents=True)
        for name in ("summary.json", "curves.csv", "config.json"):
            if (ROOT / d / run / name).is_file():
                shutil.copy(ROOT / d / run / name, tmp_path / d / run / name)
    r = ermrl("reproduce", "observed_units_lr3e4", "--root", tmp_path)
    assert r.returncode == 0, r.stderr
    table = (ROOT / d / "lr3e-4-vs-1e-4.md").read_text(encoding="utf-8")
    assert (tmp_path / d / "lr3e-4-vs-1e-4.md").read_text(encoding="utf-8") == table
    assert (tmp_path / d / "lr3e-4-vs-1e-4.png").read_bytes()[:4] == b"\x89PNG"


def test_a_failing_command_ends_the_run_with_one_line(tmp_path):
    from ermrl.errors import RunFailed
    from ermrl.experiments.reproduction import execute

    (tmp_path / "docs" / "data").mkdir(parents=True)
    bad = Step("bad", (), "a comparison of a missing file",
               (compare("a=missing/summary.json", tee="out/summary.md"),
                Run("ermrl", ("train",), skip_if=(Exists("docs/data"),))))
    with pytest.raises(RunFailed, match=r"^step bad: `ermrl compare a=missing/summary.json \| tee out/summary.md` "
                                        r"exited with status 2; rerun `ermrl reproduce bad` to resume it$"):
        execute.run_step(bad, tmp_path, write=lambda line: None)
    assert not (tmp_path / "out").exists()  # the table is written only by a command that ends well


def test_phi_flags_read_a_committed_journal():
    """The Φ* of the pendulum-lr1e-4 study as `ermrl train` flags: its selected trial's, every value as the float's
    repr."""
    from ermrl.evolution.record import decode_study_record
    from ermrl.evolution.selection import chosen_trial
    from ermrl.evolution.study import ATTR, load_study

    flags = PhiFlags("docs/data/pendulum-lr1e-4/studies.log", "pendulum-lr1e-4").resolve(ROOT)
    study = load_study(str(DATA / "pendulum-lr1e-4" / "studies.log"), "pendulum-lr1e-4")
    _, phi, how = chosen_trial(study, decode_study_record(study.user_attrs[ATTR]), None)
    assert flags == ["--sr", repr(float(phi.sr[0])), "--leak-rate", repr(float(phi.lr[0])), "--iss",
                     repr(float(phi.iss[0]))]
    assert float(flags[1]) == phi.sr[0]


def _tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_file()}


def test_collect_stash_and_restore_keep_test_phases_in_the_repository(tmp_path):
    """A committed test phase's files (docs/data/observed-units-small/100-of-100/test/) as a run left them, with its
    agents, its report.html and episodes.csv, and another test phase still training (OUT.partial/): collect copies
    the small files only; stash keeps the partial one beside the journal and drops it once it is gone from runs/;
    restore on a fresh checkout puts back both the partial folder and the finished test phase."""
    committed = DATA / "observed-units-small" / "100-of-100" / "test"
    runs = tmp_path / "runs" / "experiments" / "observed-units-small"
    shutil.copytree(committed, runs / "100-of-100" / "test")
    (runs / "100-of-100" / "test" / "agents" / "ermrl").mkdir(parents=True)
    (runs / "100-of-100" / "test" / "agents" / "ermrl" / "seed1000.npz").write_bytes(b"agent")
    (runs / "100-of-100" / "report.html").write_text("<html>")
    (runs / "100-of-100" / "selection.json").write_text("{}")
    (runs / "100-of-100" / "test" / "episodes.csv").write_text("episodes")
    partial = runs / "1000-of-1000" / "test.partial"
    partial.mkdir(parents=True)
    (partial / "ermrl.npz").write_bytes(b"model")
    (partial / "settings.json").write_text("{}")
    (partial / "summary.json").write_text("[]")  # inside a partial folder: not collected
    data = tmp_path / "docs" / "data" / "observed-units-small"

    folders.collect(tmp_path, "observed-units-small")
    assert _tree(data) == {f"100-of-100/test/{f.name}" for f in committed.iterdir()} | {"100-of-100/selection.json"}
    assert (data / "100-of-100" / "test" / "summary.json").read_bytes() == (committed / "summary.json").read_bytes()

    folders.stash(tmp_path, "observed-units-small")
    assert _tree(data / "1000-of-1000") == {"test.partial/ermrl.npz", "test.partial/settings.json",
                                            "test.partial/summary.json"}

    fresh = tmp_path / "fresh"  # a fresh checkout: docs/data only
    shutil.copytree(tmp_path / "docs", fresh / "docs")
    folders.restore(fresh, "observed-units-small")
    back = fresh / "runs" / "experiments" / "observed-units-small"
    assert _tree(back) == {f"100-of-100/test/{f.name}" for f in committed.iterdir()} | {
        "1000-of-1000/test.partial/ermrl.npz", "1000-of-1000/test.partial/settings.json",
        "1000-of-1000/test.partial/summary.json"}

    shutil.rmtree(partial)  # its test phase was written
    folders.stash(tmp_path, "observed-units-small")
    assert not (data / "1000-of-1000" / "test.partial").exists()


def test_a_journal_elsewhere_with_the_experiments_studies_is_found(tmp_path):
    own = tmp_path / "docs" / "data" / "locomotion-small"
    other = tmp_path / "docs" / "data" / "moved"
    own.mkdir(parents=True)
    other.mkdir(parents=True)
    (own / "studies.log").write_text('{"study_name": "locomotion-small-ant-2res"}\n')
    (other / "studies.log").write_text('{"op_code": 0, "study_name": "locomotion-small-ant-2res"}\n')
    (other / "unrelated.log").write_text('{"study_name": "locomotion-medium-ant-2res"}\n')
    assert folders.journals_elsewhere(tmp_path, "locomotion", "small") == [other / "studies.log"]

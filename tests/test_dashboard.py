"""`ermrl dashboard` as a user runs it: a real tiny study, the server as a subprocess, its HTTP API (and the page in
headless Chromium when it is installed), and the one-line errors before anything is served."""

import json
import re
import queue
import shutil
import socket
import subprocess
import sys
import threading
import urllib.request

import optuna
import pytest

from ermrl.evolution.study import make_storage

from cli_runs import COMMAND, ermrl as cli

STUDY = "dash-tiny-study"


@pytest.fixture(scope="module")
def study_dir(tmp_path_factory):
    """A study made by `ermrl evolve` (2 trials, 1 seed, 2048 steps) in runs/STUDY/study.db under a fresh folder,
    and the same study copied by Optuna into a journal file beside it."""
    root = tmp_path_factory.mktemp("dashboard")
    r = cli("evolve", "--env", "CartPoleNoVel-v1", "--trials", "2", "--popsize", "2", "--sampler", "random",
            "--seeds", "1", "--timesteps", "2048", "--fixed-iss", "1.0", "--study", STUDY, "--quiet", "--no-estimate",
            cwd=root)
    assert r.returncode == 0, r.stderr
    optuna.copy_study(from_study_name=STUDY, from_storage=f"sqlite:///{root}/runs/{STUDY}/study.db",
                      to_storage=make_storage(str(root / "studies.log")))
    return root


class Dashboard:
    """`ermrl dashboard ARGS --port 0` in a subprocess; ``url`` is the study page it prints once it listens."""

    def __init__(self, *args, cwd):
        self.proc = subprocess.Popen([*COMMAND, "dashboard", *args, "--port", "0"],
                                     cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        lines = queue.Queue()
        threading.Thread(target=lambda: [lines.put(line) for line in self.proc.stdout] + [lines.put("")],
                         daemon=True).start()
        self.lines = []
        while not self.lines or not self.lines[-1].startswith("open "):
            try:
                line = lines.get(timeout=300)  # a guard against a hung start, not a timing
            except queue.Empty:
                line = ""
            if not line:
                self.proc.kill()
                raise AssertionError(f"the dashboard did not start: {self.lines} {self.proc.communicate()[1]}")
            self.lines.append(line.rstrip("\n"))
        self.url = self.lines[-1].split()[1]
        self.base = self.url.split("/dashboard/")[0]

    def get(self, path: str):
        with urllib.request.urlopen(self.base + path, timeout=60) as response:
            return response.status, response.read().decode()

    def close(self):
        self.proc.terminate()
        self.proc.communicate(timeout=60)


@pytest.mark.parametrize("storage", ["default", "sqlite", "journal", "postgresql"])
def test_the_dashboard_serves_the_study_and_its_trials(study_dir, storage, request):
    db = study_dir / "runs" / STUDY / "study.db"
    expected = optuna.load_study(study_name=STUDY, storage=f"sqlite:///{db}")
    url = {"default": None, "sqlite": f"sqlite:///{db}", "journal": str(study_dir / "studies.log")}.get(storage)
    if storage == "postgresql":  # the same study copied by Optuna into a fresh database of a throwaway server
        url = request.getfixturevalue("postgres_url")
        optuna.copy_study(from_study_name=STUDY, from_storage=f"sqlite:///{db}", to_storage=make_storage(url))
    server = Dashboard("--study", STUDY, *(["--storage", url] if url else []), cwd=study_dir)
    try:
        shown = url or f"sqlite:///runs/{STUDY}/study.db"
        assert server.lines[0] == f"optuna-dashboard for study {STUDY!r} in {shown}"
        assert re.fullmatch(r"open http://127\.0\.0\.1:\d+/dashboard/studies/\d+ \(Ctrl-C stops it\)", server.lines[1])
        study_id = int(server.url.rsplit("/", 1)[1])
        status, body = server.get("/api/studies")
        assert status == 200
        listed = {s["study_name"]: s["study_id"] for s in json.loads(body)["study_summaries"]}
        assert listed == {STUDY: study_id}
        status, body = server.get(f"/api/studies/{study_id}")
        assert status == 200
        detail = json.loads(body)
        assert detail["name"] == STUDY
        assert [t["number"] for t in detail["trials"]] == [0, 1]
        for t, want in zip(detail["trials"], expected.trials):
            assert t["state"] == "Complete"
            assert t["values"] == [pytest.approx(want.value)]
            assert {p["name"]: p["param_internal_value"] for p in t["params"]} == pytest.approx(want.params)
            attrs = {a["key"]: a["value"] for a in t["user_attrs"]}
            assert {"generation", "phi", "seed_fitness", "curve_final"} <= set(attrs)
            assert json.loads(attrs["seed_fitness"]) == pytest.approx(want.user_attrs["seed_fitness"])
        record = dict((a["key"], a["value"]) for a in detail["user_attrs"])["ermrl"]
        assert record.startswith('{"version": 2, "env_id": "CartPoleNoVel-v1"')  # cut at 1024 characters
        status, page = server.get(f"/dashboard/studies/{study_id}")
        assert status == 200 and "<title>Optuna Dashboard</title>" in page
    finally:
        server.close()


@pytest.mark.skipif(shutil.which("chromium") is None, reason="Debian's chromium is not installed (make system-deps)")
def test_the_study_page_renders_in_headless_chromium(study_dir):
    best = optuna.load_study(study_name=STUDY, storage=f"sqlite:///{study_dir}/runs/{STUDY}/study.db").best_trial
    server = Dashboard("--study", STUDY, cwd=study_dir)
    try:
        r = subprocess.run(["chromium", "--headless", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=20000",
                            "--dump-dom", server.url], capture_output=True, text=True, timeout=300)
    finally:
        server.close()
    assert r.returncode == 0, r.stderr[-2000:]
    text = re.sub(r"<[^>]+>", " ", re.sub(r"<(script|style)\b.*?</\1>", "", r.stdout, flags=re.S))
    study_id = server.url.rsplit("/", 1)[1]
    assert f"{STUDY} (id={study_id})" in text  # the page's title bar, drawn by the app from the API
    assert f"Best Trial (number={best.number})" in text
    assert "Hyperparameter Importance" in text


def test_errors_are_one_line_before_anything_is_served(study_dir, tmp_path):
    def refused(*args, cwd=tmp_path):
        r = cli("dashboard", *args, cwd=cwd)
        assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, (r.returncode, r.stdout, r.stderr)
        return r.stderr.removesuffix("\n")

    assert refused("--study", "nope") == ("ermrl dashboard: error: no study 'nope': runs/nope/study.db does not exist; "
                                          "run `ermrl evolve` first or pass --storage/--out")
    journal = tmp_path / "missing.log"
    assert refused("--study", STUDY, "--storage", str(journal)) == (
        f"ermrl dashboard: error: no study '{STUDY}': {journal} does not exist; run `ermrl evolve` first or pass "
        "--storage/--out")
    assert list(tmp_path.iterdir()) == []  # looking created no database, journal or folder
    url = f"sqlite:///{study_dir}/runs/{STUDY}/study.db"
    assert refused("--study", "other", "--storage", url) == (
        f"ermrl dashboard: error: no study 'other' in '{url}'; studies there: {STUDY}")
    assert refused("--study", STUDY, "--port", "70000", cwd=study_dir) == (
        "ermrl dashboard: error: --port 70000 is not a port; give 1..65535, or 0 for any free port")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        assert refused("--study", STUDY, "--port", str(port), cwd=study_dir) == (
            f"ermrl dashboard: error: port {port} on 127.0.0.1 is in use; pass another --port, or --port 0 for any "
            "free port")


def test_without_optuna_dashboard_the_command_says_how_to_install_it(study_dir):
    # sys.modules[name] = None is Python's own way to make an import fail as if the package were not installed
    code = ("import sys; sys.modules['optuna_dashboard'] = None; from ermrl.cli import main; "
            f"sys.exit(main(['dashboard', '--study', {STUDY!r}]))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=study_dir, timeout=300)
    assert r.returncode == 2 and r.stdout == ""
    assert r.stderr == ("ermrl dashboard: error: optuna-dashboard is not installed; install it with "
                        "pip install 'ermrl[dashboard]'\n")

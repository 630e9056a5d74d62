import os
import tempfile

# One persistent JAX compilation cache for the whole run, inherited by the CLI subprocesses: the many tests that
# compile the same program (CartPoleNoVel at a CI budget, ...) compile it once. Set before JAX initializes.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", tempfile.mkdtemp(prefix="ermrl-jax-cache-"))

from ermrl import devices  # noqa: E402

devices.setup()  # one JAX device per CPU core, before any test starts JAX's backends


# -- a throwaway PostgreSQL server (tests of many workers on one study) ---------------------------------------

import glob  # noqa: E402
import pwd  # noqa: E402
import shutil  # noqa: E402
import socket  # noqa: E402
import subprocess  # noqa: E402

import pytest  # noqa: E402


def _postgres_bindir() -> str | None:
    """The folder of initdb and pg_ctl: on PATH, else Debian's /usr/lib/postgresql/VERSION/bin (newest)."""
    found = shutil.which("initdb")
    if found and shutil.which("pg_ctl"):
        return os.path.dirname(os.path.realpath(found))
    dirs = sorted(glob.glob("/usr/lib/postgresql/*/bin"), key=lambda d: int(d.split("/")[-2].split(".")[0]))
    return next((d for d in reversed(dirs) if os.path.exists(f"{d}/initdb") and os.path.exists(f"{d}/pg_ctl")), None)


@pytest.fixture(scope="session")
def postgres_server():
    """A PostgreSQL server of its own on 127.0.0.1 (a free port, trust auth, data in a temporary folder), run
    as an unprivileged user when the tests run as root (PostgreSQL refuses root). Yields the URL of its
    maintenance database. Skips only where the binaries are missing (`make system-deps` installs them)."""
    bindir = _postgres_bindir()
    if bindir is None:
        pytest.skip("PostgreSQL is not installed (initdb, pg_ctl); `make system-deps` installs Debian's postgresql")
    root = tempfile.mkdtemp(prefix="ermrl-pg-")  # under /tmp, which an unprivileged user can reach
    run_as = []
    if os.geteuid() == 0:
        user = next((u for u in ("postgres", "nobody") if _has_user(u)), None)
        if user is None:
            pytest.skip("running as root without a 'postgres' or 'nobody' user to run PostgreSQL as")
        entry = pwd.getpwnam(user)
        os.chown(root, entry.pw_uid, entry.pw_gid)
        run_as = ["setpriv", f"--reuid={entry.pw_uid}", f"--regid={entry.pw_gid}", "--clear-groups"]
    data = os.path.join(root, "data")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    env = {**os.environ, "LC_ALL": "C"}
    subprocess.run([*run_as, f"{bindir}/initdb", "-D", data, "-U", "ermrl", "--auth=trust", "-E", "UTF8",
                    "--no-sync"], check=True, capture_output=True, env=env)
    options = f"-c listen_addresses=127.0.0.1 -p {port} -c unix_socket_directories={root} -c fsync=off"
    subprocess.run([*run_as, f"{bindir}/pg_ctl", "-D", data, "-o", options, "-l", os.path.join(root, "log"), "-w",
                    "start"], check=True, capture_output=True, env=env)
    try:
        yield f"postgresql://ermrl@127.0.0.1:{port}/postgres"
    finally:
        subprocess.run([*run_as, f"{bindir}/pg_ctl", "-D", data, "-m", "immediate", "stop"], capture_output=True)
        shutil.rmtree(root, ignore_errors=True)


def _has_user(name: str) -> bool:
    try:
        pwd.getpwnam(name)
        return True
    except KeyError:
        return False


@pytest.fixture
def postgres_url(postgres_server, request):
    """A fresh, empty database on the session's PostgreSQL server, for one test."""
    import psycopg

    import hashlib

    # PostgreSQL cuts names at 63 bytes: a readable prefix, then a hash of the whole test id (parametrized ones too)
    readable = "".join(c if c.isalnum() else "_" for c in request.node.name.lower())[:40]
    name = f"t_{readable}_{hashlib.sha1(request.node.nodeid.encode()).hexdigest()[:8]}"
    with psycopg.connect(postgres_server, autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{name}"')
        conn.execute(f'CREATE DATABASE "{name}"')
    return postgres_server.rsplit("/", 1)[0] + "/" + name


# -- the smoke study of CartPoleNoVel that the budget and estimate tests share ----------------------------------

@pytest.fixture(scope="session")
def evolved(tmp_path_factory):
    """smoke_study's study, evolved, selected and tested once per session by the CLI; tests read it, and copy it
    before they change it."""
    from smoke_study import evolve

    return evolve(tmp_path_factory.mktemp("evolved"))


# -- real saved agents that the analyses of saved agents share ------------------------------------------------

@pytest.fixture(scope="session")
def saved(tmp_path_factory):
    """Real saved agents, trained once per session by the CLI: PendulumNoVel ER-MRL and plain PPO (2 seeds each,
    200-step episodes) and CartPoleNoVel ER-MRL (1 seed, whose early episodes are far shorter). Tests read the
    agents and may write figures beside them."""
    from cli_runs import ermrl

    folder = tmp_path_factory.mktemp("saved")
    for name, env, seeds, extra in [("ermrl", "PendulumNoVel-v1", "2", []),
                                    ("ppo", "PendulumNoVel-v1", "2", ["--no-reservoir"]),
                                    ("cartpole", "CartPoleNoVel-v1", "1", [])]:
        r = ermrl("train", "--env", env, "--timesteps", "2048", "--seeds", seeds, "--quiet", "--out",
                  str(folder / name), *extra)
        assert r.returncode == 0, r.stderr
    return folder

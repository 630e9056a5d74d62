"""JAX's persistent compilation cache under the CLI: a second process of the same shapes reads its programs back
instead of compiling them, with the same results; a damaged cache, one turned off or one that cannot be written
never fails a run. Real processes (the cache is per folder, across processes)."""

from __future__ import annotations

from pathlib import Path

from ermrl import compile_cache

from cli_runs import ermrl_process

TRAIN = ["train", "--env", "CartPoleNoVel-v1", "--seeds", "2", "--timesteps", "4096", "--quiet"]


def _train(cwd: Path, out: str, cache: Path):
    r = ermrl_process(*TRAIN, "--out", out, cwd=cwd, env={"ERMRL_COMPILE_CACHE": str(cache), "JAX_LOG_COMPILES": "1"})
    assert r.returncode == 0, r.stderr
    return r


def test_a_second_run_reads_its_programs_from_the_cache_and_a_damaged_one_is_compiled_again(tmp_path):
    cache = tmp_path / "cache"
    first = _train(tmp_path, "a", cache)
    entries = sorted(cache.glob("*-cache"))
    assert {p.name.split("-")[0] for p in entries} >= {"jit_init", "jit_iteration"}
    assert "Persistent compilation cache hit for 'jit_iteration'" not in first.stderr

    second = _train(tmp_path, "b", cache)
    assert "Persistent compilation cache hit for 'jit_iteration'" in second.stderr
    assert (tmp_path / "b/episodes.csv").read_bytes() == (tmp_path / "a/episodes.csv").read_bytes()

    for entry in entries:  # cut short, as a process killed while writing it would leave it
        entry.write_bytes(entry.read_bytes()[:100])
    third = _train(tmp_path, "c", cache)
    assert "Persistent compilation cache hit for 'jit_iteration'" not in third.stderr
    assert (tmp_path / "c/episodes.csv").read_bytes() == (tmp_path / "a/episodes.csv").read_bytes()


def test_where_the_cache_lives_and_when_it_is_off(tmp_path, monkeypatch):
    import jax

    monkeypatch.delenv(compile_cache.VARIABLE, raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert compile_cache.folder() == tmp_path / "xdg" / "ermrl" / "jax"
    given = jax.config.jax_compilation_cache_dir  # this suite's own (conftest.py): kept when ermrl's is not set
    assert given and compile_cache.enable() == Path(given) and jax.config.jax_compilation_cache_dir == given
    for off in ("off", "0", "OFF "):
        monkeypatch.setenv(compile_cache.VARIABLE, off)
        assert compile_cache.folder() is None and compile_cache.enable() is None
    monkeypatch.setenv(compile_cache.VARIABLE, "/proc/ermrl/cache")  # no one can create anything there
    assert compile_cache.enable() is None
    assert not (tmp_path / "xdg").exists()
    existing = tmp_path / "cache"
    assert compile_cache._writable(existing) and existing.is_dir() and not list(existing.iterdir())  # made once
    before = existing.stat().st_mtime_ns
    assert compile_cache._writable(existing) and existing.stat().st_mtime_ns == before  # then only asked

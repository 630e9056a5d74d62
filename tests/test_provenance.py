"""The software versions recorded with every result (ermrl.provenance), and the warning a study resumed under
other versions gives."""

import importlib.metadata
import pathlib
import platform

import jax
import mujoco
import optuna

import ermrl
from ermrl import provenance
from ermrl.evolution.config import EvolveConfig
from ermrl.evolution.search_space import SearchSpace
from ermrl.evolution.study import SOFTWARE_ATTR, make_sampler, open_study
from ermrl.evolution.record import encode_study_record
from ermrl.training import TrainConfig

optuna.logging.set_verbosity(optuna.logging.WARNING)


def test_software_names_the_installed_versions_and_none_for_a_missing_package(monkeypatch):
    monkeypatch.delenv("XLA_FLAGS", raising=False)
    versions = provenance.software()
    assert list(versions) == ["python", "cpu", "xla_flags", *provenance.PACKAGES]
    assert versions["python"] == platform.python_version() and versions["xla_flags"] is None
    assert versions["cpu"] == provenance.cpu() and versions["cpu"].startswith(platform.machine())
    assert versions["jax"] == jax.__version__ and versions["mujoco"] == mujoco.__version__
    assert versions["optuna"] == optuna.__version__ == importlib.metadata.version("optuna")
    monkeypatch.setattr(provenance, "PACKAGES", ("jax", "no-such-distribution"))
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_max_isa=AVX2")
    assert provenance.software() == {"python": platform.python_version(), "cpu": provenance.cpu(),
                                     "xla_flags": "--xla_cpu_max_isa=AVX2", "jax": jax.__version__,
                                     "no-such-distribution": None}


def test_ermrl_run_from_a_source_tree_records_its_own_version(monkeypatch):
    # on a lent GPU machine ermrl runs from the checkout (PYTHONPATH), not installed: no distribution metadata
    installed = importlib.metadata.version

    def version(name):
        if name == "ermrl":
            raise importlib.metadata.PackageNotFoundError(name)
        return installed(name)

    monkeypatch.setattr(importlib.metadata, "version", version)
    versions = provenance.software()
    assert versions["ermrl"] == ermrl.__version__ is not None
    assert versions["jax"] == jax.__version__


def test_cpu_names_the_widest_vector_extension_xla_may_use(tmp_path):
    machine = platform.machine()
    info = tmp_path / "cpuinfo"
    info.write_text("processor\t: 0\nflags\t\t: fpu sse4_2 avx avx2 fma\n\nprocessor\t: 1\n")
    assert provenance.cpu(info) == f"{machine} AVX2"
    info.write_text("flags\t\t: sse4_2 avx avx2 avx512f avx512bw\n")
    assert provenance.cpu(info) == f"{machine} AVX-512"
    info.write_text("flags\t\t: fp asimd\n")
    assert provenance.cpu(info) == machine
    assert provenance.cpu(tmp_path / "missing") == machine
    real = pathlib.Path("/proc/cpuinfo")
    if real.is_file():  # this machine: the widest extension among its flags
        flags = next(line for line in real.read_text().splitlines() if line.startswith("flags")).split()
        widest = next((name for flag, name in provenance.ISA_FLAGS if flag in flags), None)
        assert provenance.cpu() == (machine if widest is None else f"{machine} {widest}")


def test_differences_name_each_changed_package_and_skip_what_one_side_lacks():
    now = {"python": "3.11.2", "jax": "0.10.2", "mujoco": "4.0.0", "gymnax": None}
    assert provenance.differences({"python": "3.11.2", "jax": "0.10.1", "mujoco": "4.0.0", "old": "1"}, now) == [
        "jax 0.10.1 → 0.10.2"]
    assert provenance.differences({"jax": "0.10.2", "mujoco": "3.17.0", "gymnax": "1.0.1"}, now) == [
        "mujoco 3.17.0 → 4.0.0", "gymnax 1.0.1 → None"]
    assert provenance.differences({}, now) == []


def test_a_study_records_its_versions_and_warns_when_resumed_under_others(tmp_path, capsys):
    config = EvolveConfig(train=TrainConfig(env_id="CartPoleNoVel-v1", total_timesteps=2048),
                          space=SearchSpace(fixed_iss=1.0), trials=1, seeds=1)
    url = f"journal:{tmp_path / 'studies.log'}"
    study = open_study(url, "s", make_sampler("random", 6, 0), encode_study_record(config))
    assert study.user_attrs[SOFTWARE_ATTR] == provenance.software()
    open_study(url, "s", make_sampler("random", 6, 0), encode_study_record(config))
    assert capsys.readouterr().err == ""  # same versions: silent

    older = {**provenance.software(), "jax": "0.4.0", "mujoco": "3.0.0"}
    study.set_user_attr(SOFTWARE_ATTR, older)
    again = open_study(url, "s", make_sampler("random", 6, 0), encode_study_record(config))
    assert capsys.readouterr().err == (
        f"warning: study 's' was started with other versions (jax 0.4.0 → {jax.__version__}, mujoco 3.0.0 → "
        f"{mujoco.__version__}); its new trials will not match what the first versions would compute, seed for "
        "seed\n")
    assert again.user_attrs[SOFTWARE_ATTR] == older  # the record of the start is kept

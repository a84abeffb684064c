"""The environment a run records (peg_ctrl.environment), the BLAS kernels peg_ctrl pins, and
the start perturbation."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from peg_ctrl.environment import (
    PACKAGES,
    describe,
    differences,
    environment,
    environment_id,
    start_perturbation,
)
from peg_ctrl.errors import ConfigError


def test_the_record_names_versions_cpu_blas_and_the_lock() -> None:
    env = environment()
    assert set(env["packages"]) == set(PACKAGES) and env["packages"]["mujoco"]
    assert env["python"].count(".") == 2 and env["cpu"]
    assert env["blas"]["library"] == "OpenBLAS" and env["blas"]["kernels"] and env["blas"]["threads"] == 1
    assert env["lock"]["file"] == "requirements/lock.txt" and len(env["lock"]["sha256"]) == 16
    assert env["lock"]["off_lock"] == []  # make install installs the lock
    assert len(environment_id()) == 12 and environment_id() == environment_id(json.loads(json.dumps(env)))
    line = describe(env)
    assert "\n" not in line and f"mujoco {env['packages']['mujoco']}" in line and "kernels" in line


def test_differences_name_what_moved_in_both_records() -> None:
    mine = environment()
    theirs = json.loads(json.dumps(mine))
    assert differences(theirs, mine) == []
    theirs["packages"]["mujoco"] = "3.3.0"
    theirs["blas"]["kernels"] = "Haswell"
    theirs["variables"]["OPENBLAS_CORETYPE"] = "Haswell"
    found = differences(theirs, mine)
    assert f"mujoco: {mine['packages']['mujoco']} here, 3.3.0 in the study" in found
    assert f"BLAS kernels: {mine['blas']['kernels']} here, Haswell in the study" in found
    assert len(found) == 3  # the lock the same


@pytest.mark.parametrize(("text", "value"), [("", 0.0), ("1e-12", 1e-12), (" -1e-10 ", -1e-10)])
def test_the_start_perturbation_reads_metres(
    monkeypatch: pytest.MonkeyPatch, text: str, value: float
) -> None:
    monkeypatch.setenv("PEG_CTRL_START_PERTURBATION", text)
    assert start_perturbation() == value


@pytest.mark.parametrize("text", ["abc", "nan", "0.01"])
def test_a_bad_start_perturbation_is_named(monkeypatch: pytest.MonkeyPatch, text: str) -> None:
    monkeypatch.setenv("PEG_CTRL_START_PERTURBATION", text)
    with pytest.raises(ConfigError, match=f"PEG_CTRL_START_PERTURBATION='{text}'"):
        start_perturbation()


def _kernels(**env: str) -> dict[str, str]:
    """The BLAS kernels and variables of a new process that imports peg_ctrl, then numpy."""
    base = {k: v for k, v in os.environ.items() if not k.startswith(("OPENBLAS_CORETYPE", "PEG_CTRL_BLAS"))}
    code = (
        "import json, peg_ctrl, numpy; from peg_ctrl.environment import environment; e = environment(); "
        "print(json.dumps({'kernels': e['blas']['kernels'], **e['variables']}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], env={**base, **env}, capture_output=True, text=True, check=True
    )
    return dict(json.loads(out.stdout))


_AVX512 = {"avx512f", "avx512dq", "avx512bw", "avx512vl"} <= set(environment()["cpu_flags"])


@pytest.mark.skipif(not _AVX512, reason="the pin applies to CPUs with AVX-512")
def test_peg_ctrl_runs_the_studies_kernels_and_records_what_it_overrode() -> None:
    pinned = _kernels(OPENBLAS_CORETYPE="Haswell")
    assert pinned["kernels"] == "SkylakeX" and pinned["PEG_CTRL_BLAS_OVERRODE"] == "Haswell"
    kept = _kernels(OPENBLAS_CORETYPE="Haswell", PEG_CTRL_BLAS="keep")
    assert kept["kernels"] == "Haswell" and "PEG_CTRL_BLAS_OVERRODE" not in kept

"""glibc malloc tuned for one identification at a time (:func:`wmrid.runtime.limits.tune_malloc`): applied in the
command-line process and on fleet workers, left alone under an address-space cap and where the user's environment
sets malloc's thresholds (unless a fleet worker overrides Dask's).  Each case runs in its own small process, so
this test process keeps glibc's defaults."""

from __future__ import annotations

import os
import resource
import subprocess
import sys

import pytest
from locations import ROOT_DIR

ROOT = ROOT_DIR


def _tuned(env_extra: dict[str, str] | None = None, cap: int | None = None, override: bool = False) -> str:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    env.update(env_extra or {})

    def limit() -> None:
        if cap is not None:
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    code = f"from wmrid.runtime.limits import tune_malloc; print(tune_malloc({override}))"
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, preexec_fn=limit, check=True
    )
    return out.stdout.strip()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="mallopt is glibc's")
def test_malloc_is_tuned_unless_capped_or_set_by_the_user():
    assert _tuned() == "True"
    assert _tuned(cap=4 << 30) == "False"
    assert _tuned({"MALLOC_TRIM_THRESHOLD_": "65536"}) == "False"
    assert _tuned({"MALLOC_TRIM_THRESHOLD_": "65536"}, override=True) == "True"  # a fleet worker under Dask's nanny

"""hystid's fits run on one BLAS thread, even when numpy was imported first."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from hystid.blas import THREAD_VARIABLES

PROBE = """
import json, numpy, threadpoolctl
blas = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
if not blas:
    print(json.dumps(None)); raise SystemExit
threadpoolctl.threadpool_limits(limits=2, user_api="blas")  # the user's own setting
import hystid
from hystid.blas import one_blas_thread

def threads():
    return max(i["num_threads"] for i in threadpoolctl.threadpool_info()
               if i["user_api"] == "blas")

@one_blas_thread
def inner():
    return threads()

@one_blas_thread
def outer():
    return [threads(), inner(), threads()]

print(json.dumps({"before": threads(), "during": outer(), "after": threads()}))
"""


def _probe(env: dict) -> dict | None:
    out = subprocess.run([sys.executable, "-c", PROBE], env=env, capture_output=True,
                         text=True, timeout=120, check=True)
    return json.loads(out.stdout)


def test_numpy_first_then_fits_limit_blas_to_one_thread_and_give_it_back():
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    seen = _probe(env)
    if seen is None:
        pytest.skip("threadpoolctl finds no BLAS library in numpy here")
    assert seen["before"] == 2 and seen["after"] == 2  # the user's setting, kept
    assert seen["during"] == [1, 1, 1]  # nested entry points too


def test_a_thread_count_the_environment_sets_is_left_alone():
    env = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    env["OMP_NUM_THREADS"] = "2"
    seen = _probe(env)
    if seen is None:
        pytest.skip("threadpoolctl finds no BLAS library in numpy here")
    assert seen["during"] == [2, 2, 2]

"""Test-session set-up: one BLAS thread, the campaign's summary at the end, and the
explorer's TestClient (the `client` fixture)."""

from __future__ import annotations

import ctypes
import glob
import json
import os

import pytest


def _one_blas_thread() -> None:
    """Run OpenBLAS (numpy's and scipy's bundled copies) on one thread.

    On the project's 2-core machine a threaded ``eigvals`` of a 160 x 160 matrix
    takes 0.8 s against 7 ms on one thread (the threads contend); the campaign
    solves thousands of such eigenproblems. Same as ``OPENBLAS_NUM_THREADS=1``,
    which cannot be set from here once numpy is loaded. Results do not change.
    """
    import numpy
    import scipy

    for pkg in (numpy, scipy):
        libs = os.path.join(os.path.dirname(os.path.dirname(pkg.__file__)), pkg.__name__ + ".libs")
        for path in glob.glob(os.path.join(libs, "*openblas*.so*")):
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for sym in ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                        "openblas_set_num_threads64_", "openblas_set_num_threads"):
                f = getattr(lib, sym, None)
                if f is not None:
                    f(1)
                    break


_one_blas_thread()


def pytest_terminal_summary(terminalreporter, exitstatus, config):
    """Print the campaign's failure summary (and write it to out/campaign-report[-shard].json)."""
    from references import campaign

    if not campaign.RESULTS:
        return
    terminalreporter.write_sep("=", "hapstab vs brute-force campaign")
    terminalreporter.write_line(campaign.summary())
    shard = os.environ.get("HAPSTAB_CAMPAIGN_SHARD", "").replace("/", "of")
    path = os.path.join("out", f"campaign-report{'-' + shard if shard else ''}.json")
    try:
        os.makedirs("out", exist_ok=True)
        with open(path, "w") as f:
            json.dump(campaign.report_json(), f, indent=1)
        terminalreporter.write_line(f"full report: {path}")
    except OSError:
        pass


@pytest.fixture(scope="module")
def client():
    """The explorer's app behind starlette's TestClient (tests/explorer/test_explorer_*.py; they
    skip without starlette and httpx before asking for it)."""
    import warnings

    from hapstab.explorer.app import create_app

    with warnings.catch_warnings():    # starlette 1.x: "httpx with TestClient is deprecated"
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient

        with TestClient(create_app(), base_url="http://127.0.0.1", raise_server_exceptions=False) as c:
            yield c

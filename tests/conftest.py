"""Suite-wide guards."""

import signal

import pytest


@pytest.fixture(autouse=True)
def _sigint_disposition_kept():
    """A test must leave the process's SIGINT disposition as it found it.

    The Ctrl-C tests start children that inherit it: a test that leaves SIGINT ignored makes
    them fail far from the cause (a child with SIG_IGN never sees the interrupt). This guard
    names the test that changed it.
    """
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    if after is not before:
        signal.signal(signal.SIGINT, before)
        pytest.fail(f"SIGINT disposition changed by this test: {before!r} -> {after!r}")

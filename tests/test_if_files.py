"""The session's IF-file factory (``conftest.if_files``): one set per set of arguments, and a
set changed in place is refused the next time a test asks for it."""

import pytest


def test_same_arguments_share_one_set_and_a_changed_set_is_refused(if_files):
    a = if_files(0.01, name="guard")
    assert if_files(0.01, sampling_rate_hz=2.5e6, name="guard") is a
    assert sorted(p.name for p in a.if_file.parent.iterdir()) == sorted(
        p.name for p in a.files.values())
    stray = a.if_file.parent / "guard_run"          # a run written beside the shared file
    stray.mkdir()
    try:
        with pytest.raises(pytest.fail.Exception, match=r"changed since it was made \(guard_run\)"):
            if_files(0.01, name="guard")
    finally:
        stray.rmdir()
    data = a.metadata.read_bytes()
    a.metadata.write_bytes(data + b"\n")            # a member changed in place
    try:
        with pytest.raises(pytest.fail.Exception, match=r"\(guard\.json\)"):
            if_files(0.01, name="guard")
    finally:
        a.metadata.write_bytes(data)

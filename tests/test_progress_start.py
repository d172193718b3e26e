"""Progress starts at once (issue 28 item 4): on a terminal, ``run`` and ``generate`` show a
status line before the numba kernels are imported (about 2 s), and nothing with --no-progress
or when stderr is not a terminal."""

import fcntl
import os
import pty
import struct
import subprocess
import sys
import termios

#: Marks on stderr the moment numba is first imported (inside main(), by the command).
_MARK_NUMBA = """
import sys
from importlib.abc import MetaPathFinder

class Mark(MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "numba":
            sys.meta_path.remove(self)
            sys.stderr.write("<numba>")
            sys.stderr.flush()
        return None

sys.meta_path.insert(0, Mark())
from sdr_di.cli import main
sys.exit(main(sys.argv[1:]))
"""

GEN = ["generate", "--duration", "0.02", "--fs", "2.5e6"]


def _stderr_on_a_terminal(argv):
    """The process's stderr as a terminal shows it (a pseudo-terminal), and its status."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # 100 columns
    proc = subprocess.Popen([sys.executable, "-c", _MARK_NUMBA, *argv], stdout=subprocess.PIPE,
                            stderr=slave, stdin=subprocess.DEVNULL)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:  # EIO: the process closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    proc.communicate(timeout=120)
    return b"".join(chunks).decode(errors="replace"), proc.returncode


def test_status_line_before_the_kernels_load(tmp_path):
    err, rc = _stderr_on_a_terminal([*GEN, "--out", str(tmp_path / "o")])
    assert rc == 0, err
    assert err.startswith("sdr-di: loading"), err[:200]
    assert err.index("sdr-di: loading") < err.index("<numba>") < err.index("generate default")


def test_no_status_line_with_no_progress(tmp_path):
    err, rc = _stderr_on_a_terminal([*GEN, "--no-progress", "--out", str(tmp_path / "o")])
    assert rc == 0 and "sdr-di: loading" not in err, err


def test_error_after_the_status_line_clears_it(tmp_path):
    err, rc = _stderr_on_a_terminal([*GEN, "--cn0", "-500", "--out", str(tmp_path / "o")])
    assert rc == 2, err
    # the status, then the line cleared, then the one-line error
    assert err.startswith("sdr-di: loading") and "\r\x1b[Ksdr-di: error: --cn0" in err, err
    assert not (tmp_path / "o").exists()
    err, rc = _stderr_on_a_terminal([*GEN, "--frobnicate"])  # the argument parser's refusal
    assert rc == 2 and "\r\x1b[Ksdr-di: error: unrecognized arguments: --frobnicate" in err, err


def test_not_a_terminal_no_status_line(tmp_path):
    res = subprocess.run([sys.executable, "-m", "sdr_di.cli", *GEN, "--out",
                          str(tmp_path / "o")], capture_output=True, text=True, timeout=120)
    assert res.returncode == 0 and "sdr-di: loading" not in res.stderr, res.stderr

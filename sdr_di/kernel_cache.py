"""Whether the receiver's numba kernels are compiled on this machine yet.

The kernels are compiled on their first call and cached (``cache=True``: index files
``MODULE.FUNCTION-LINE.pyXY.nbi`` in the ``__pycache__`` beside the module, or under
``NUMBA_CACHE_DIR``). The first run on a machine spends about 30 s there while its progress
bar sits at 0 % ("acquisition"); :func:`first_use_note` is the line that says so (issue 49
item 14), shown in the progress bar of ``run`` and ``acquire`` until the first epoch.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

#: The kernel modules a run calls first (acquisition and correlation), by package folder.
FIRST_KERNELS = ("receiver/_numba_acquire.py", "receiver/_numba_correlate_bits.py")

#: What the first run on a machine says while the kernels compile.
NOTE = "compiling the signal-processing kernels for this machine, once (about 30 s)"


def _cache_dir(module: Path) -> Path:
    """Where numba keeps the index files of ``module``'s kernels."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        return Path(root) / Path(*module.parent.resolve().parts[1:])
    return module.parent / "__pycache__"


def kernels_cached() -> bool:
    """True when every module of :data:`FIRST_KERNELS` has cached kernels for this Python."""
    pkg = Path(__file__).resolve().parent
    tag = f"py{sys.version_info.major}{sys.version_info.minor}"
    for rel in FIRST_KERNELS:
        module = pkg / rel
        d = _cache_dir(module)
        try:
            if not any(d.glob(f"{module.stem}.*.{tag}.nbi")):
                return False
        except OSError:
            return False
    return True


def first_use_note() -> str:
    """:data:`NOTE` when the kernels are not cached yet, else ``""``."""
    return "" if kernels_cached() else NOTE

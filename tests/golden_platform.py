"""The numerical platform of the golden records (tests/golden/): one x86-64 instruction level for every library.

Iterative algorithms amplify the last bit of a sum, and BLAS (OpenBLAS, for numpy and for
scipy), numpy's own loops and numba's compiled kernels each pick their code for the CPU they run
on: records written on a CPU with AVX-512 differ from those of a CPU with AVX2 alone by far more
than rounding. The golden records are therefore written and checked with every one of them held
to the x86-64-v3 level (AVX2 and FMA, the Haswell kernels), which any x86-64 CPU of the last
decade runs, whatever else it has: :data:`PINNED` is that environment.

One library cannot be held: onnxruntime, which speaks the generated speech corpus, picks its
kernels by the CPU and has no setting for it. Records of experiments on generated speech are
therefore only compared on a CPU of the same class as the one that wrote them
(:func:`cpu_class`, kept in ``tests/golden/PLATFORM``).

``python tests/golden_platform.py COMMAND ...`` runs a command in the pinned environment and,
with ``--write-class FILE``, first writes this CPU's class to FILE (``make golden``).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

#: The environment that holds OpenBLAS, numpy's dispatched loops and numba to the x86-64-v3 level.
PINNED = {
    "OPENBLAS_CORETYPE": "Haswell",
    # numpy >= 2.4 names the AVX-512 levels X86_V4, AVX512_ICL, AVX512_SPR; older ones AVX512F ... (unknown or
    # unsupported names are ignored)
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX "
                                "AVX512_CLX AVX512_CNL",
    "NUMBA_CPU_NAME": "haswell",
    "NUMBA_CPU_FEATURES": "",
}

#: The file in tests/golden/ that names the CPU class of the machine that wrote the records.
CLASS_FILE = Path(__file__).resolve().parent / "golden" / "PLATFORM"


def _flags() -> set[str]:
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return set()
    for line in text.splitlines():
        if line.startswith("flags"):
            return set(line.split(":", 1)[1].split())
    return set()


def can_pin() -> tuple[bool, str]:
    """Whether this machine runs the pinned environment (x86-64 with AVX2 and FMA), and why not."""
    machine = platform.machine().lower()
    if machine not in ("x86_64", "amd64"):
        return False, f"the golden records are of x86-64 (AVX2, FMA); this machine is {machine}"
    flags = _flags()
    if not {"avx2", "fma"} <= flags:
        return False, "the golden records are of x86-64 with AVX2 and FMA; this CPU lacks them"
    return True, ""


def cpu_class() -> str:
    """This CPU's class as onnxruntime's kernels see it: ``x86_64 avx512`` or ``x86_64 avx2`` (the machine's name)."""
    flags = _flags()
    level = "avx512" if {"avx512f", "avx512bw", "avx512dq", "avx512vl"} <= flags else "avx2"
    return f"{platform.machine().lower()} {level}"


def pinned_environ() -> dict[str, str]:
    """``os.environ`` with :data:`PINNED` set."""
    env = dict(os.environ)
    env.update(PINNED)
    return env


def main(argv: list[str]) -> int:
    if argv[:1] == ["--write-class"]:
        Path(argv[1]).write_text(cpu_class() + "\n")
        argv = argv[2:]
    ok, why = can_pin()
    if not ok:
        print(f"golden_platform: {why}", file=sys.stderr)
        return 2
    return subprocess.call(argv, env=pinned_environ())


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

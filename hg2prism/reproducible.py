"""The same numbers, to the last bit, on every Linux x86-64 machine with AVX2.

Two libraries pick their code by the processor they run on, and both decide last bits here:
- the OpenBLAS that numpy's and scipy's wheels bring: SciPy's sparse LU (SuperLU: the exact
  solves of P2's games and of the certified strategies) calls its kernels, and the kernels for
  AVX-512 add up in another order than those for AVX2. On a Xeon with AVX-512 the games'
  values differed from an AMD EPYC's in their last bits, and some of P2's and P1's ties then
  went the other way (other strategies in a delayed world's games, other explorer pages);
- numpy's own SIMD loops: its exp and log for AVX-512 differ from AVX2's in the last bit
  (the log-likelihood ratios written into hypergame.prism).
So `import hg2prism`, before numpy is imported, pins OpenBLAS to its Haswell kernels (AVX2 and
FMA, which every x86-64 processor since 2013-2015 has) and, on a processor with AVX-512, keeps
numpy to its AVX2 loops: every such machine then computes the same bits (on an AVX-512 Xeon,
byte for byte what an AVX2-only EPYC wrote). OpenBLAS and numpy read the choice when they load,
so it is too late once numpy is imported: a process that imported numpy before hg2prism keeps
its own code, and so do the processes it starts. A variable the user set is kept, and
HG2PRISM_KERNELS=native leaves both libraries to their own choice (faster dense linear algebra
on AVX-512, other last bits). docs/cli.md, "Reproducible numbers".
"""

from __future__ import annotations

import os
import platform
import sys

KERNEL = "Haswell"       # OpenBLAS's AVX2 + FMA kernels
NEEDS = {"avx2", "fma"}  # the processor flags they use (else they would stop the process)
# numpy's dispatch groups above AVX2 (numpy 2.4's names; older releases name them otherwise
# and are left alone): NPY_DISABLE_CPU_FEATURES turns them off
NUMPY_AVX512 = "X86_V4 AVX512_ICL AVX512_SPR"
OPT_OUT = "HG2PRISM_KERNELS"     # "native": no pinning


def _cpu_flags() -> set[str]:
    """The processor's flags (Linux's /proc/cpuinfo; empty elsewhere or if unreadable)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as handle:
            for line in handle:
                if line.startswith("flags"):
                    return set(line.partition(":")[2].split())
    except OSError:
        pass
    return set()


def _numpy_at_least(major: int, minor: int) -> bool:
    import importlib.metadata

    try:
        parts = importlib.metadata.version("numpy").split(".")[:2]
        return (int(parts[0]), int(parts[1])) >= (major, minor)
    except (importlib.metadata.PackageNotFoundError, ValueError, IndexError):
        return False


def pin_kernels() -> None:
    """Pin OpenBLAS to its Haswell kernels and numpy to its AVX2 loops where they can run,
    before numpy loads: not where the user set either variable or HG2PRISM_KERNELS=native,
    and not once numpy or scipy is loaded (too late for this process, and the processes it
    starts, Dask's workers say, must compute as it does)."""
    if os.environ.get(OPT_OUT, "").lower() == "native" or _loaded():
        return
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return
    flags = _cpu_flags()
    if not NEEDS <= flags:
        return
    os.environ.setdefault("OPENBLAS_CORETYPE", KERNEL)
    if "avx512f" in flags and _numpy_at_least(2, 4):
        os.environ.setdefault("NPY_DISABLE_CPU_FEATURES", NUMPY_AVX512)


def kernels() -> dict[str, str]:
    """What results.json's `software` records of the code that decides the last bits:
    `blas_kernels`, the name the OpenBLAS of numpy's and scipy's wheels reports ("Haswell";
    "numpy SkylakeX, scipy Haswell" where they differ; "unknown" for another BLAS), and
    `numpy_simd`, numpy's dispatch groups in use ("X86_V3": AVX2)."""
    import numpy

    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
        simd = " ".join(f for f in __cpu_dispatch__ if __cpu_features__.get(f)) or "baseline"
    except ImportError:
        simd = "unknown"
    return {"blas_kernels": _blas_kernels(numpy), "numpy_simd": simd}


def _blas_kernels(numpy) -> str:
    import ctypes
    import glob
    import importlib

    names = {}
    for package, symbol in (("numpy", "scipy_openblas_get_corename64_"),
                            ("scipy", "scipy_openblas_get_corename")):
        root = os.path.dirname(importlib.import_module(package).__file__)
        for path in (glob.glob(os.path.join(root + ".libs", "*openblas*"))
                     + glob.glob(os.path.join(root, ".dylibs", "*openblas*"))):
            try:
                get = getattr(ctypes.CDLL(path), symbol)
            except (OSError, AttributeError):
                continue
            get.restype = ctypes.c_char_p
            names[package] = get().decode(errors="replace")
    if not names:
        return "unknown"
    if len(set(names.values())) == 1:
        return next(iter(names.values()))
    return ", ".join(f"{package} {name}" for package, name in names.items())


def _loaded() -> bool:
    return "numpy" in sys.modules or "scipy" in sys.modules

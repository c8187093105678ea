"""The same numbers, to the last bit, on every x86-64 machine with AVX2.

numpy and scipy ship OpenBLAS built for many processors, which picks its kernels by the
processor it runs on. SciPy's sparse LU (SuperLU, the exact solves of P2's games and of the
certified strategies) calls those kernels, and the kernels for AVX-512 add up in another order
than those for AVX2: on a Xeon with AVX-512 the games' values differed from an AMD EPYC's in
their last bits, and so did every number computed from them (the log-likelihood ratios written
into hypergame.prism, the CUSUM scores, the Pmax values' last digits). Pinning OpenBLAS to its
Haswell kernels (AVX2 and FMA, which every x86-64 processor since 2013 has) gives every such
machine the same bits. OpenBLAS reads the choice when it loads, that is when numpy is first
imported, so `import hg2prism` sets it before importing numpy; a process that imported numpy
before hg2prism (or that sets OPENBLAS_CORETYPE itself, which is respected) keeps its own
kernels, and its last bits may differ (docs/cli.md, "Reproducible numbers").
"""

from __future__ import annotations

import os
import platform
import sys

KERNEL = "Haswell"       # OpenBLAS's AVX2 + FMA kernels
NEEDS = {"avx2", "fma"}  # the processor flags they use (else they would stop the process)


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


def pin_blas_kernels() -> None:
    """Set OPENBLAS_CORETYPE to the Haswell kernels where they can run, before numpy loads
    OpenBLAS; not where the user set it, and not where numpy or scipy is loaded already (too
    late for this process, and the processes it starts, Dask's workers say, must use the
    kernels it uses)."""
    if "OPENBLAS_CORETYPE" in os.environ or _loaded():
        return
    if platform.machine().lower() in ("x86_64", "amd64") and NEEDS <= _cpu_flags():
        os.environ["OPENBLAS_CORETYPE"] = KERNEL


def blas_kernels() -> str:
    """OpenBLAS's kernels in use, as results.json's `software` records them: the name the
    OpenBLAS of numpy's and scipy's wheels reports ("Haswell"; "numpy SkylakeX, scipy Haswell"
    where they differ), "unknown" where they have none (another BLAS)."""
    import ctypes
    import glob
    import importlib

    names = {}
    for package, symbol in (("numpy", "scipy_openblas_get_corename64_"),
                            ("scipy", "scipy_openblas_get_corename")):
        libraries = os.path.dirname(importlib.import_module(package).__file__) + ".libs"
        for path in glob.glob(os.path.join(libraries, "libscipy_openblas*.so*")):
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

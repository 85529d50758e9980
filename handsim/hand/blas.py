"""The BLAS kernels this process computes with.

NumPy's matrix products go through OpenBLAS, which picks its kernels by CPU (or by
``OPENBLAS_CORETYPE``) when it loads; other kernels round differently in the last bit, so a
result kept between processes (a cached mesh) is only the one a process would make when the
kernels are the same.
"""

from __future__ import annotations


def blas_kernels() -> str:
    """``"api:architecture"`` of each BLAS library loaded, e.g. ``"openblas:SkylakeX"``."""
    import numpy  # noqa: F401 (loads NumPy's BLAS)
    from threadpoolctl import threadpool_info

    names = {
        f"{lib.get('internal_api')}:{lib.get('architecture')}"
        for lib in threadpool_info()
        if lib.get("user_api") == "blas"
    }
    return ",".join(sorted(names)) or "none"

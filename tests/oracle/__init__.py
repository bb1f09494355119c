"""The numpy oracle of the mortar kernels: the package's first implementation, kept for tests.

The package has one implementation of its kernels, compiled C (``dolfinx_mortar/kernels``).
The vectorized numpy kernels it had before are here, outside the package, so that the tests
can check the compiled ones against a second implementation of the same integrals and their
derivatives: :mod:`.line2_numpy` (2D) and :mod:`.surface3_numpy` (3D), each with a kernel of
the package's contract (:class:`~.line2_numpy.Line2Kernel`,
:class:`~.surface3_numpy.Surface3Kernel`) and the function ``pair_quantities``.

:func:`use_oracle` makes the stencils (:mod:`dolfinx_mortar.stencils`) run them, so that an
interface, an assembled system or a whole solve can be compared (what
``DOLFINX_MORTAR_KERNELS=numpy`` did while the package had both). Nothing in
``dolfinx_mortar`` imports this package (``tests/test_structure.py`` checks it).
"""

from __future__ import annotations

import contextlib

from . import line2_numpy, surface3_numpy


@contextlib.contextmanager
def use_oracle():
    """Within the block, the stencils of both dimensions run the numpy kernels."""
    from dolfinx_mortar import stencils

    saved = stencils.Line2Stencil.kernel, stencils.Surface3Stencil.kernel
    stencils.Line2Stencil.kernel = line2_numpy.Line2Kernel()
    stencils.Surface3Stencil.kernel = surface3_numpy.Surface3Kernel()
    try:
        yield
    finally:
        stencils.Line2Stencil.kernel, stencils.Surface3Stencil.kernel = saved


__all__ = ["line2_numpy", "surface3_numpy", "use_oracle"]

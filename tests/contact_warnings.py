"""ContactWarnings as a user sees them: shown once, by rank 0 (dolfinx_mortar.diagnostics.warn)."""

from __future__ import annotations

import contextlib
import re
import warnings

from mpi4py import MPI

from dolfinx_mortar.diagnostics import ContactWarning


@contextlib.contextmanager
def warns_on_rank_zero(match: str | None = None, comm: MPI.Intracomm = MPI.COMM_WORLD):
    """Like ``pytest.warns(ContactWarning, match=match)`` on rank 0 (a warning whose text
    matches the regular expression is shown); on every other rank, no ContactWarning is
    shown. Yields the list of the ContactWarnings shown on this rank, filled on exit."""
    shown: list = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield shown
    shown += [w for w in caught if issubclass(w.category, ContactWarning)]
    if comm.rank == 0:
        texts = [str(w.message) for w in shown]
        assert texts, "no ContactWarning was shown on rank 0"
        if match is not None:
            assert any(re.search(match, t) for t in texts), f"none matches {match!r}: {texts}"
    else:
        assert shown == [], f"rank {comm.rank} showed {len(shown)} ContactWarning(s)"

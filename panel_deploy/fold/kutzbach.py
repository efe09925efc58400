"""Spatial Kutzbach mobility of a hinged panel assembly."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from ..errors import DesignError
from .design import Cell


def kutzbach_dof(bodies: int, hinges: int) -> int:
    """Spatial Kutzbach criterion with one body as ground and revolute joints.

    Parameters
    ----------
    bodies : int
        Number of rigid bodies ``n``, ground included (>= 1).
    hinges : int
        Number of revolute joints ``j`` (>= 0).

    Returns
    -------
    int
        ``6 (n - 1) - 5 j``; negative values mean an overconstrained count.

    Raises
    ------
    DesignError
        If a count is not a non-negative integer or `bodies` is 0.

    Examples
    --------
    >>> kutzbach_dof(16, 16)  # the paper's 4 x 4 circuit
    10
    >>> kutzbach_dof(12, 12)  # after merging the middle columns
    6
    """
    for name, v, lo in (("bodies", bodies, 1), ("hinges", hinges, 0)):
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise DesignError(f"{name}: expected an integer >= {lo}, got {v!r}")
    return 6 * (bodies - 1) - 5 * hinges


def body_joints(
    bodies: Sequence[Sequence[Cell]], hinges: Iterable[tuple[Cell, Cell]]
) -> dict[tuple[int, int], list[tuple[Cell, Cell]]]:
    """Group hinge segments by the pair of bodies they join.

    Parameters
    ----------
    bodies : sequence of sequence of Cell
        The cells of each body; every hinge cell must be in exactly one.
    hinges : iterable of (Cell, Cell)

    Returns
    -------
    dict
        ``(i, j) -> [segments]`` with ``i < j`` body indices. Hinges inside one
        body (rigid after merging) are left out. Segments of one entry are one
        revolute joint when they are collinear (as :mod:`.merge` guarantees).
    """
    owner = {c: i for i, body in enumerate(bodies) for c in body}
    joints: dict[tuple[int, int], list] = {}
    for u, v in hinges:
        i, j = owner[u], owner[v]
        if i != j:
            joints.setdefault((min(i, j), max(i, j)), []).append((u, v))
    return joints


def assembly_dof(bodies: Sequence[Sequence[Cell]], hinges: Iterable[tuple[Cell, Cell]]) -> int:
    """Kutzbach mobility of bodies joined by hinges, collinear segments counting once."""
    return kutzbach_dof(len(bodies), len(body_joints(bodies, hinges)))

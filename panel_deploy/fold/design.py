"""Data types of a fold design: circuit, hinges, stowed state, merges.

Conventions (shared by the whole package):

* Cells are ``(row, col)`` tuples, 1-based, row 1 at the top, column 1 on the left.
* Flat array frame: x along the columns (to the right), y along the rows towards
  row 1 (upwards), z normal to the array, out of the top facet. Cell ``(r, c)`` of an
  R x C array of panels ``a x b x t`` has its centroid at
  ``x = (c - (C + 1) / 2) a``, ``y = ((R + 1) / 2 - r) b``, ``z = 0``.
* A hinge lies on the shared edge of two cells, on the top facet (z = +t/2) or on
  the bottom facet (z = -t/2). Its angle is 0 flat and pi folded.
* Stowed placements are rigid motions of the flat array frame made of rotations by
  pi about axes parallel to x or y, so every rotation is a diagonal matrix of +-1
  with determinant +1 and every translation is a whole number of cell pitches in x
  and y and a whole number of thicknesses in z. They are stored in those units
  (``offset`` = (dx / a, dy / b, dz / t)), so a design does not depend on the panel
  size.
* Stacks: the footprint is two side-by-side cell positions (in flat-array cell
  coordinates, possibly outside the array); stack 0 is the footprint's first cell.
  Layer 0 is the top of the stacks (largest z), layers count downwards.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

Cell = tuple[int, int]
Facet = Literal["top", "bottom"]


@dataclass(frozen=True)
class CellPlacement:
    """Where one cell of the flat array lies in the stowed package.

    Attributes
    ----------
    cell : Cell
    stack : int
        0 or 1, index into :attr:`StowedState.footprint`.
    layer : int
        0 at the top of the stacks, increasing downwards.
    face_up : bool
        True if the cell's top facet still points along +z.
    rotation : tuple of 3 ints
        Diagonal of the rotation matrix (each +1 or -1, product +1).
    offset : tuple of 3 ints
        Translation (dx / a, dy / b, dz / t) applied after the rotation; the
        rotation acts about the flat-array origin.
    """

    cell: Cell
    stack: int
    layer: int
    face_up: bool
    rotation: tuple[int, int, int]
    offset: tuple[int, int, int]


@dataclass(frozen=True)
class HingeState:
    """Stowed angle and facet of one hinge of the circuit.

    ``angle`` is 0 (stays flat, the two cells side by side on one layer) or pi
    (folded, the two cells on adjacent layers of one stack); ``facet`` is the
    facet the hinge line lies on, ``"top"`` (z = +t/2) or ``"bottom"``.
    """

    cells: tuple[Cell, Cell]
    angle: float
    facet: Facet


@dataclass(frozen=True)
class StowedState:
    """A two-stack stowed package of a circuit design.

    Attributes
    ----------
    footprint : tuple of two Cell
        Flat-array cell positions occupied by stack 0 and stack 1.
    layers : int
        Number of layers of each stack (cells / 2).
    placements : dict Cell -> CellPlacement
    hinges : dict tuple[Cell, Cell] -> HingeState
        Keyed by the sorted cell pair.
    """

    footprint: tuple[Cell, Cell]
    layers: int
    placements: dict
    hinges: dict

    def stack_order(self, stack: int) -> list[Cell]:
        """Cells of one stack, top layer first."""
        cells = [p for p in self.placements.values() if p.stack == stack]
        return [p.cell for p in sorted(cells, key=lambda p: p.layer)]


@dataclass(frozen=True)
class Merge:
    """Two or more cells made into one rigid body, and why."""

    cells: tuple[Cell, ...]
    reason: str


@dataclass(frozen=True)
class FoldDesign:
    """A circuit design of an R x C array, with its packing verdict.

    Attributes
    ----------
    rows, cols : int
    circuit : tuple of Cell
        The Hamiltonian circuit in visiting order (the closing edge back to the
        first cell is implied).
    hinges : tuple of (Cell, Cell)
        Sorted cell pairs whose shared edge the circuit crosses.
    slits : tuple of (Cell, Cell)
        Sorted adjacent cell pairs without a hinge.
    stowed : StowedState or None
        A two-stack package, or None when none exists.
    reason : str
        Why no package exists ("" when one does).
    bodies : tuple of tuple of Cell
        Cells of each rigid body after merging (one cell each without merging).
    merges : tuple of Merge
    dof_cells, dof_bodies : int
        Spatial Kutzbach mobility before and after merging.
    ground : Cell or None
        The cell held at the identity in :attr:`stowed` (the ground panel).
    refused : tuple of Merge
        Requested or candidate merges that were not made, each with the reason.
    """

    rows: int
    cols: int
    circuit: tuple
    hinges: tuple
    slits: tuple
    stowed: StowedState | None
    reason: str
    bodies: tuple
    merges: tuple
    dof_cells: int
    dof_bodies: int
    ground: Cell | None = None
    refused: tuple = ()

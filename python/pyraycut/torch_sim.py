"""TorchSim's neighbour-list function on raycut's search, for torch-sim models (MACE, SevenNet,
pair potentials, ...): pass ``neighbor_list`` wherever a model takes ``neighbor_list_fn``.

>>> from torch_sim.models.pair_potential import PairPotentialModel
>>> import pyraycut.torch_sim
>>> model = PairPotentialModel(pair_fn, cutoff=2.5,
...                            neighbor_list_fn=pyraycut.torch_sim.neighbor_list)

It has the signature and the conventions of ``torch_sim.neighbors.torchsim_nl``:
``(positions, cell, pbc, cutoff, system_idx, self_interaction=False) -> (mapping,
system_mapping, shifts_idx)``. Every pair appears both ways; the shifts are integer image
counts, stored in the cell's dtype, with ``r_ij = positions[j] - positions[i] + shifts_idx @
cell[system]`` (row vectors). torch-sim itself is not imported: this module needs PyTorch only.
"""
from __future__ import annotations

from typing import Any

import torch

from . import neighbor_list as _neighbor_list

__all__ = ["neighbor_list"]


def _boxes(cell: torch.Tensor) -> torch.Tensor:
    """The cell as pyraycut takes it: (3, 3) for every system, else (B, 3, 3). torch-sim passes
    (B, 3, 3) row-vector cells; its functions also accept (3 B, 3), the boxes stacked."""
    if not isinstance(cell, torch.Tensor):
        raise ValueError(f"pyraycut.torch_sim.neighbor_list: cell must be a tensor (zeros for "
                         f"open systems), got {type(cell).__name__}")
    if cell.dim() == 3 or cell.shape == (3, 3):
        return cell
    if cell.dim() == 2 and cell.shape[1] == 3 and cell.shape[0] % 3 == 0:
        return cell.reshape(-1, 3, 3)
    raise ValueError(f"pyraycut.torch_sim.neighbor_list: cell must be (3, 3), (B, 3, 3) or "
                     f"(3 B, 3), got {tuple(cell.shape)}")


def neighbor_list(positions: torch.Tensor, cell: torch.Tensor, pbc: Any, cutoff: Any,
                  system_idx: torch.Tensor, self_interaction: bool = False,
                  ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Every pair of atoms closer than ``cutoff`` in each system, as ``torchsim_nl`` returns
    them.

    - ``positions``: (N, 3), float32 or float64, wrapped into the cell or not (the shifts refer
      to the positions as given);
    - ``cell``: (B, 3, 3) row-vector cells (``state.row_vector_cell``), or (3 B, 3), or one
      (3, 3) for every system; rows of open axes may be zero;
    - ``pbc``: one bool, (3,) or (B, 3) bools;
    - ``cutoff``: a number or a 0-d tensor;
    - ``system_idx``: (N,) integers, sorted: the system of each atom;
    - ``self_interaction``: also list (i, i) with zero shift for every atom, after the pairs.

    Returns ``mapping`` (2, P) int64 (row 0 the centre atom i, row 1 its neighbour j, sorted by
    i, the self pairs after them), ``system_mapping`` (P,) int64, and ``shifts_idx`` (P, 3) in
    the cell's dtype. An atom's own periodic images (i, i, S != 0) are pairs like any other.
    """
    if not isinstance(system_idx, torch.Tensor) or system_idx.dim() != 1 or \
            system_idx.shape[0] != positions.shape[0]:
        raise ValueError(f"pyraycut.torch_sim.neighbor_list: system_idx must be a tensor of "
                         f"shape ({positions.shape[0]},), one system per atom, got "
                         f"{getattr(system_idx, 'shape', type(system_idx).__name__)}")
    i, j, shifts = _neighbor_list("ijS", positions, cutoff, cell=_boxes(cell), pbc=pbc,
                                  batch=system_idx)
    if self_interaction:
        atoms = torch.arange(positions.shape[0], dtype=i.dtype, device=i.device)
        i = torch.cat((i, atoms))
        j = torch.cat((j, atoms))
        shifts = torch.cat((shifts, shifts.new_zeros((positions.shape[0], 3))))
    system_idx = system_idx.to(device=i.device, dtype=torch.int64)
    return torch.stack((i, j)), system_idx[i], shifts.to(cell.dtype)

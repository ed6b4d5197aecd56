"""The GRU equations in plain linear ops, for the places where the fused kernels cannot go: `torch.func.vmap` over
stacked runs (emml/rl/packed.py) has no batching rule for `aten::gru.input` and loops `aten::gru_cell` per sample.

PyTorch's GRU (gates r, z, n in that order in the stacked weights), which these reproduce within float tolerance:
r = sigmoid(W_ir x + b_ir + W_hr h + b_hr), z = sigmoid(W_iz x + b_iz + W_hz h + b_hz),
n = tanh(W_in x + b_in + r * (W_hn h + b_hn)), h' = (1 - z) * n + z * h.
"""

from __future__ import annotations

import torch
from torch import Tensor, nn
from torch.nn.functional import linear


def gru_update(gates_x: Tensor, h: Tensor, weight_hh: Tensor, bias_hh: Tensor) -> Tensor:
    """One GRU step from the input side's gate pre-activations ``gates_x`` = W_ih x + b_ih (..., 3H) and h (..., H)."""
    xr, xz, xn = gates_x.chunk(3, dim=-1)
    hr, hz, hn = linear(h, weight_hh, bias_hh).chunk(3, dim=-1)
    r, z = torch.sigmoid(xr + hr), torch.sigmoid(xz + hz)
    n = torch.tanh(xn + r * hn)
    return (1 - z) * n + z * h


def gru_cell(cell: nn.GRUCell, x: Tensor, h: Tensor) -> Tensor:
    """`cell(x, h)` in linear ops."""
    return gru_update(linear(x, cell.weight_ih, cell.bias_ih), h, cell.weight_hh, cell.bias_hh)


def gru_scan(gru: nn.GRU, x: Tensor) -> Tensor:
    """`gru(x)[0]` from zero state in linear ops, for a one-layer batch-first GRU: (N, L, in) -> (N, L, H)."""
    if gru.num_layers != 1 or not gru.batch_first or gru.bidirectional or not gru.bias:
        raise ValueError("gru_scan implements a one-layer, unidirectional, batch-first GRU with biases")
    gates_x = linear(x, gru.weight_ih_l0, gru.bias_ih_l0)  # the input side of every step at once
    h = x.new_zeros(x.shape[0], gru.hidden_size)
    outs = []
    for t in range(x.shape[1]):
        h = gru_update(gates_x[:, t], h, gru.weight_hh_l0, gru.bias_hh_l0)
        outs.append(h)
    return torch.stack(outs, dim=1)

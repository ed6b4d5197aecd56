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


class _Recurrence(torch.autograd.Function):
    """The GRU over T steps with resets, from the input side's gate pre-activations of every step, with a
    hand-written backward (backpropagation through time): the forward records no autograd graph, and the weight
    gradients are two matmuls over all T·B rows instead of T small ones. Same equations and operation order as
    PyTorch's CPU `gru_cell` (h' = n + z * (h - n)); gradients checked in float64 (tests/models/test_gru.py)."""

    @staticmethod
    def forward(ctx, gates_x: Tensor, h: Tensor, keep: Tensor, weight_hh: Tensor, bias_hh: Tensor) -> Tensor:
        hidden = h.shape[-1]
        h_in = gates_x.new_empty(gates_x.shape[0], *h.shape)  # the state each step starts from (after its reset)
        out, n = torch.empty_like(h_in), torch.empty_like(h_in)
        gates_h = torch.empty_like(gates_x)  # W_hh h + b_hh, then r and z in place of their pre-activations
        weight_t = weight_hh.t()
        steps = zip(gates_x.unbind(0), keep.unbind(0), h_in.unbind(0), gates_h.unbind(0), n.unbind(0), out.unbind(0))
        for gx, keep_t, h_t, gh, n_t, out_t in steps:
            h = torch.mul(h, keep_t, out=h_t)
            torch.addmm(bias_hh, h, weight_t, out=gh)
            rz = gh[:, : 2 * hidden]
            rz.add_(gx[:, : 2 * hidden]).sigmoid_()  # r, z
            torch.mul(gh[:, 2 * hidden :], rz[:, :hidden], out=n_t).add_(gx[:, 2 * hidden :]).tanh_()
            h = torch.sub(h, n_t, out=out_t).mul_(rz[:, hidden:]).add_(n_t)  # h' = n + (h - n) * z
        ctx.save_for_backward(keep, weight_hh, h_in, gates_h, n)
        return out

    @staticmethod
    def backward(ctx, grad_out: Tensor):
        keep, weight_hh, h_in, gates_h, n = ctx.saved_tensors
        hidden = grad_out.shape[-1]
        r, z, hn = gates_h.split(hidden, dim=-1)  # hn: W_hn h + b_hn, the h side of the n gate
        grad_gates_h = torch.empty_like(gates_h)  # d(W_hh h + b_hh) per step
        grad_xn = torch.empty_like(grad_out)  # d(W_in x + b_in): the h side's n gate times r
        grad_h = torch.zeros_like(grad_out[0])
        per_step = (x.unbind(0) for x in (grad_out, r, z, n, hn, h_in, keep, grad_gates_h, grad_xn))
        for g_out, r_t, z_t, n_t, hn_t, h_t, keep_t, grad_gh, grad_xn_t in reversed(list(zip(*per_step))):
            g = grad_h + g_out  # d h'_t
            grad_a = torch.mul(g * (1 - z_t), 1 - n_t * n_t, out=grad_xn_t)  # through (1 - z) * n and tanh
            gr, gz, gn = grad_gh.split(hidden, dim=-1)
            torch.mul(grad_a * hn_t, r_t * (1 - r_t), out=gr)
            torch.mul(g * (h_t - n_t), z_t * (1 - z_t), out=gz)
            torch.mul(grad_a, r_t, out=gn)
            grad_h = torch.addmm(g * z_t, grad_gh, weight_hh).mul_(keep_t)
        grad_gates_x = torch.cat([grad_gates_h[..., : 2 * hidden], grad_xn], dim=-1)
        flat = grad_gates_h.reshape(-1, 3 * hidden)
        return grad_gates_x, grad_h, None, flat.t() @ h_in.reshape(-1, hidden), flat.sum(0)


def gru_sequence(cell: nn.GRUCell, x: Tensor, h: Tensor, keep: Tensor) -> Tensor:
    """``cell`` over x (T, B, in) from h (B, H), the state multiplied by ``keep`` (T, B, 1) before each step (0 at an
    episode start): (T, B, H), every step's output. Equal within float tolerance to the loop
    ``h = cell(x[t], h * keep[t])``; the input side of all T steps is one matmul (`_Recurrence`)."""
    gates_x = linear(x, cell.weight_ih, cell.bias_ih)
    return _Recurrence.apply(gates_x, h, keep, cell.weight_hh, cell.bias_hh)

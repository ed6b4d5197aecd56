import pytest
import torch
from torch import nn

from emml.models.gru import _Recurrence, gru_sequence


def _inputs(dtype, steps=7, batch=3, size=5, hidden=4, seed=0):
    gen = torch.Generator().manual_seed(seed)
    cell = nn.GRUCell(size, hidden).to(dtype)
    x = torch.randn(steps, batch, size, generator=gen, dtype=dtype, requires_grad=True)
    h = torch.randn(batch, hidden, generator=gen, dtype=dtype, requires_grad=True)
    keep = (torch.rand(steps, batch, 1, generator=gen) > 0.3).to(dtype)  # resets at ~30% of the steps
    return cell, x, h, keep


def test_recurrence_gradients_match_finite_differences():
    cell, x, h, keep = _inputs(torch.float64)
    gates_x = torch.nn.functional.linear(x, cell.weight_ih, cell.bias_ih).detach().requires_grad_()
    args = (gates_x, h, keep, cell.weight_hh, cell.bias_hh)
    assert torch.autograd.gradcheck(_Recurrence.apply, args)


@pytest.mark.parametrize("seed", [0, 1])
def test_gru_sequence_equals_the_cell_loop_outputs_and_gradients(seed):
    """The policy's recurrence (resets by ``keep``): outputs and every gradient as the GRUCell loop it replaces."""
    cell, x, h, keep = _inputs(torch.float32, steps=128, batch=8, size=64, hidden=32, seed=seed)
    outs, state = [], h
    for t in range(x.shape[0]):
        state = cell(x[t], state * keep[t])
        outs.append(state)
    ref = torch.stack(outs)
    weights = torch.randn_like(ref)
    ref_grads = torch.autograd.grad((ref * weights).sum(), [x, h, *cell.parameters()])
    out = gru_sequence(cell, x, h, keep)
    grads = torch.autograd.grad((out * weights).sum(), [x, h, *cell.parameters()])
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-6)
    for got, want in zip(grads, ref_grads):
        # float32 sums over 128 steps x 8 in another order: single-threaded, seed 0 differs by 2e-5 in one weight
        # of W_ih; a wrong gradient is off by orders more
        torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-4)

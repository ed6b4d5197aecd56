"""The image encoder's geometry, without torch: the size of the conv3 grid for an input size.

Appendix A: conv1 32@8×8 stride 4, conv2 64@4×4 stride 2, conv3 V@3×3 stride 2, no padding (paper silent; with
none, 168×300 gives the 9×17 grid). The env needs it for the aux label grid, the models for their layer sizes.
"""

from __future__ import annotations

CONV_LAYERS = ((8, 4), (4, 2), (3, 2))
"""(kernel, stride) of conv1..conv3."""


def _min_input_size() -> int:
    size = 1
    for kernel, stride in reversed(CONV_LAYERS):
        size = (size - 1) * stride + kernel
    return size


MIN_INPUT_SIZE = _min_input_size()
"""Smallest image height/width the conv stack accepts (36): conv3 keeps one output cell."""


def conv_output_size(height: int, width: int) -> tuple[int, int]:
    """(h, w) of the conv3 output for an input of height × width; a ValueError naming the field if empty."""
    out = []
    for name, size in (("height", height), ("width", width)):
        if isinstance(size, bool) or not isinstance(size, int) or size < MIN_INPUT_SIZE:
            raise ValueError(
                f"{name}={size!r} is too small for the image encoder: {name} must be an integer >= {MIN_INPUT_SIZE}"
            )
        n = size
        for kernel, stride in CONV_LAYERS:
            n = (n - kernel) // stride + 1
        out.append(n)
    return out[0], out[1]


def receptive_field() -> tuple[int, int]:
    """(size, jump) in input pixels of one conv3 cell: its receptive field and the step between two cells."""
    size, jump = 1, 1
    for kernel, stride in CONV_LAYERS:
        size += (kernel - 1) * jump
        jump *= stride
    return size, jump


def pixel_cells(render: int, observed: int, cells: int) -> list[int]:
    """For each of ``render`` engine pixels along one axis, the conv3 cell whose receptive field is centred
    nearest to it once the frame is resized to ``observed`` pixels (paper silent on how labels meet the grid).

    The conv stack has no padding, so its cells are centred at (size-1)/2 + k·jump input pixels, not at an even
    partition of the frame: at 168×300 the partition's last column lies a whole cell (16 px) right of conv3's."""
    size, jump = receptive_field()
    out = []
    for r in range(render):
        x = (r + 0.5) * observed / render - 0.5  # pixel centre in observation coordinates
        out.append(min(max(round((x - (size - 1) / 2) / jump), 0), cells - 1))
    return out

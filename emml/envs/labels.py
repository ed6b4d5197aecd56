"""Auxiliary task labels (paper §3.2, Figure 6): a binary V×h×w grid per frame, one channel per vocabulary word.

Cell (i, j) of a word's channel is on when any pixel of a visible object that the word describes (its class,
colour or size word) falls in that cell of an even h×w partition of the frame. The engine's label buffer gives
per-pixel object values; values are not stable across frames, so each frame's `state.labels` maps them to
actors. Words without labels — superlatives (§3.2), function words, and in the transfer experiment every word
outside the training instructions — are left out by the channel mask.
"""

from __future__ import annotations

import numpy as np

from emml.envs.objects import CLASS_TO_ACTOR
from emml.tasks.language import Dataset, Vocabulary


def default_aux_words(vocab: Vocabulary, dataset: Dataset) -> tuple[str, ...]:
    """Object, colour and size words of the vocabulary: the words a detector can see."""
    visible = (
        set(dataset.word_groups["objects"]) | set(dataset.word_groups["colors"]) | set(dataset.word_groups["sizes"])
    )
    return tuple(w for w in vocab.words if w in visible)


def channel_mask(vocab: Vocabulary, aux_words: tuple[str, ...]) -> np.ndarray:
    """bool (V,): which channels the aux loss supervises."""
    return np.array([w in aux_words for w in vocab.words], dtype=bool)


class LabelGrid:
    """Turns one frame's label buffer into the V×h×w grid, for a fixed render size and grid size."""

    def __init__(self, vocab: Vocabulary, dataset: Dataset, aux_words, render_hw, grid_hw):
        self.shape = (len(vocab), *grid_hw)
        aux = set(aux_words)
        self.channels = {
            name: np.array([vocab.index(w) for w in words.words() if w in aux], dtype=np.int64)
            for name, words in dataset.actors.items()
        }
        rh, rw = render_hw
        gh, gw = grid_hw
        self.row_cell = (np.arange(rh) * gh // rh).astype(np.int64)  # pixel row → grid row
        self.col_cell = (np.arange(rw) * gw // rw).astype(np.int64)

    def __call__(self, labels_buffer: np.ndarray, labels) -> np.ndarray:
        grid = np.zeros(self.shape, dtype=np.uint8)
        for label in labels:
            actor = CLASS_TO_ACTOR.get(label.object_name)
            if actor is None:
                continue
            chans = self.channels[actor]
            if chans.size == 0:
                continue
            y0, x0 = label.y, label.x
            box = labels_buffer[y0 : y0 + label.height, x0 : x0 + label.width]
            ys, xs = np.nonzero(box == label.value)
            if ys.size == 0:
                continue
            cells = np.unique(self.row_cell[ys + y0] * self.shape[2] + self.col_cell[xs + x0])
            grid[chans[:, None], (cells // self.shape[2])[None, :], (cells % self.shape[2])[None, :]] = 1
        return grid

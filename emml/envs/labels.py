"""Auxiliary task labels (paper §3.2, Figure 6): a binary V×h×w grid per frame, one channel per vocabulary word.

Cell (i, j) of a word's channel is on when any pixel of a visible object that the word describes (its class,
colour or size word) falls in that cell: the conv3 cell whose receptive field is centred nearest to the pixel
(emml/config/geometry.py), so that a label sits where the cell predicting it looks. The engine's label buffer gives
per-pixel object values; values are not stable across frames, so each frame's `state.labels` maps them to
actors. Words without labels — superlatives (§3.2), and in the transfer experiment every word outside the
training instructions — are left out by the channel mask; function words are supervised with all-zero labels.
"""

from __future__ import annotations

import numpy as np

from emml.config.geometry import pixel_cells
from emml.envs.objects import CLASS_TO_ACTOR
from emml.tasks.language import Dataset, Vocabulary


def default_aux_words(vocab: Vocabulary, dataset: Dataset) -> tuple[str, ...]:
    """Every word but the superlatives (§3.2: each of the V channels has a label, 1 where the word's object or
    attribute is present). Function words ('go', 'the', 'object', 'what'…) describe no object, so their labels
    are all zero: left unsupervised, the BoW gate of Eq. 1 adds their free channels to every SGN attention map."""
    unlabelled = set(dataset.word_groups["superlatives"])
    return tuple(w for w in vocab.words if w not in unlabelled)


def channel_mask(vocab: Vocabulary, aux_words: tuple[str, ...]) -> np.ndarray:
    """bool (V,): which channels the aux loss supervises."""
    return np.array([w in aux_words for w in vocab.words], dtype=bool)


class LabelGrid:
    """Turns one frame's label buffer into the V×h×w grid, for a fixed render size and grid size."""

    def __init__(
        self, vocab: Vocabulary, dataset: Dataset, aux_words, render_hw, grid_hw, observed_hw=None, class_to_actor=None
    ):
        self.shape = (len(vocab), *grid_hw)
        self.class_to_actor = CLASS_TO_ACTOR if class_to_actor is None else class_to_actor
        """Engine class name (as the label buffer reports it) → the dataset's actor name (House: furniture.py)."""
        aux = set(aux_words)
        self.channels = {
            name: np.array([vocab.index(w) for w in words.words() if w in aux], dtype=np.int64)
            for name, words in dataset.actors.items()
        }
        rh, rw = render_hw
        gh, gw = grid_hw
        if observed_hw is None:  # an even partition of the frame
            self.row_cell = (np.arange(rh) * gh // rh).astype(np.int64)  # pixel row → grid row
            self.col_cell = (np.arange(rw) * gw // rw).astype(np.int64)
        else:  # the cell whose receptive field is centred nearest (emml/config/geometry.py)
            self.row_cell = np.array(pixel_cells(rh, observed_hw[0], gh), dtype=np.int64)
            self.col_cell = np.array(pixel_cells(rw, observed_hw[1], gw), dtype=np.int64)

    def _cells(self, labels_buffer: np.ndarray, label) -> np.ndarray:
        """Flat indices of the grid cells that hold at least one pixel of one label's object."""
        y0, x0 = label.y, label.x
        box = labels_buffer[y0 : y0 + label.height, x0 : x0 + label.width]
        ys, xs = np.nonzero(box == label.value)
        return np.unique(self.row_cell[ys + y0] * self.shape[2] + self.col_cell[xs + x0])

    def __call__(self, labels_buffer: np.ndarray, labels) -> np.ndarray:
        grid = np.zeros(self.shape, dtype=np.uint8)
        for label in labels:
            actor = self.class_to_actor.get(label.object_name)
            if actor is None:
                continue
            chans = self.channels[actor]
            if chans.size == 0:
                continue
            cells = self._cells(labels_buffer, label)
            grid[chans[:, None], (cells // self.shape[2])[None, :], (cells % self.shape[2])[None, :]] = 1
        return grid

    def object_grid(self, labels_buffer: np.ndarray, labels, actor: str) -> np.ndarray:
        """uint8 (h, w): the cells that show one actor (the episode's referent) — the 'perfect x_S' control and the
        attention-on-target diagnostic read it. Word-independent, so unlabelled words do not matter."""
        grid = np.zeros(self.shape[1:], dtype=np.uint8)
        for label in labels:
            if self.class_to_actor.get(label.object_name) == actor:
                grid.flat[self._cells(labels_buffer, label)] = 1
        return grid

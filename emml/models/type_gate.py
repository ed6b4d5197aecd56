"""The 'type_gate' diagnostic control (issue 34): Eq. 4's sentence gate x_sent replaced by a gate built from the
dataset's word types, to test whether the learned gate is what fails on EQA test questions.

For a question that asks for attribute A (the dataset's `answer` of its template: 'color' or 'object'), the gate
opens every channel of A's word group (colours, or object types) and closes every other channel, the queried
object's and colour's included:

    x_GA2 = f_GA(x_SA, g),  g[i] = s if word i answers A else 0        (Eq. 4 with x_sent := g)

s is the largest entry of the model's own x_sent for the sentence, so that x_Ans = softmax(Eq. 5) keeps the
sharpness the policy was trained to read (a gate of 1 gives logits ≤ 1 over V words: a near-flat x_Ans). Which
attribute a question asks is looked up: a row whose tokens are those of one of the dataset's questions gets that
question's attribute. Any other row (an SGN instruction) keeps the model's x_sent: an instruction's x_Ans is scored
nowhere, only the policy reads it, so SGN plays exactly as without the control.

Not the paper's model: it reads the dataset's word types, which the agent is not given.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from emml.tasks.language import Dataset, Vocabulary

GROUP_OF = {"color": "colors", "object": "objects", "size": "sizes"}
"""A question's answer attribute -> the dataset's word group whose words answer it."""


class TypeGate(nn.Module):
    """tokens (N, L), x_sent (N, V) -> the gate Eq. 4 reads (N, V) under control 'type_gate' (module docstring)."""

    def __init__(self, words: tuple[str, ...], dataset: Dataset) -> None:
        super().__init__()
        vocab = Vocabulary(words)
        known = set(words)
        questions = [q for q in dataset.sentences if q.kind == "eqa" and set(q.text.split()) <= known]
        self.attributes = tuple(sorted({q.answer_attribute for q in questions}))
        """The answer attributes, in the order of the rows of `opens`."""
        length = max((len(q.text.split()) for q in questions), default=1)
        n, a, v = len(questions), len(self.attributes), len(words)
        tokens = torch.tensor([vocab.encode(q.text, length) for q in questions], dtype=torch.int64)
        asks = torch.tensor([[q.answer_attribute == x for x in self.attributes] for q in questions])
        opens = torch.tensor([[w in dataset.word_groups[GROUP_OF[x]] for w in words] for x in self.attributes])
        # non-persistent: a checkpoint's state dict is the same with or without the control
        self.register_buffer("questions", tokens.reshape(n, length), persistent=False)
        """(Q, L) the token ids of the dataset's questions (those the run's words can say), right-padded."""
        self.register_buffer("question_asks", asks.reshape(n, a).float(), persistent=False)
        """(Q, A) one-hot: the attribute each question asks for (its template's `answer`)."""
        self.register_buffer("opens", opens.reshape(a, v).float(), persistent=False)
        """(A, V) the channels of the words that answer each attribute."""

    def asks(self, tokens: Tensor) -> Tensor:
        """(N, A): one-hot of the attribute each row's question asks for; a zero row for any other sentence."""
        rows, questions = tokens, self.questions
        width = max(rows.shape[1], questions.shape[1])
        rows = F.pad(rows, (0, width - rows.shape[1]))
        questions = F.pad(questions, (0, width - questions.shape[1]))
        same = (rows[:, None, :] == questions[None, :, :]).all(dim=-1).to(self.question_asks.dtype)  # (N, Q)
        return same @ self.question_asks

    def forward(self, tokens: Tensor, x_sent: Tensor) -> Tensor:
        asks = self.asks(tokens)
        opens = (asks @ self.opens).clamp(max=1.0)  # (N, V): the asked attribute's words
        scale = x_sent.amax(dim=1, keepdim=True)  # the model's own gate strength
        question = asks.sum(dim=1, keepdim=True) > 0
        return torch.where(question, opens * scale, x_sent)  # Eq. 4's gate; SGN rows: x_sent as it is

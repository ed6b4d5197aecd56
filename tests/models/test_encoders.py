"""Encoders of Chaplot et al. 2019 (arXiv 1902.01385): conv grid arithmetic, BoW, sentence GRU."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from emml.models import conv_output_size
from emml.models.encoders import MIN_INPUT_SIZE, ImageEncoder, TextEncoder


def test_conv_output_size_paper_input():
    assert conv_output_size(168, 300) == (9, 17)
    assert conv_output_size(60, 108) == (2, 5)
    assert conv_output_size(84, 150) == (4, 8)
    assert conv_output_size(MIN_INPUT_SIZE, MIN_INPUT_SIZE) == (1, 1)


@pytest.mark.parametrize("height,width,field", [(35, 300, "height"), (168, 35, "width"), (0, 0, "height")])
def test_conv_output_size_too_small_names_field(height, width, field):
    with pytest.raises(ValueError, match=rf"{field}.*>= {MIN_INPUT_SIZE}"):
        conv_output_size(height, width)


@settings(max_examples=8, deadline=None)
@given(st.integers(36, 90), st.integers(36, 90))
def test_conv_output_size_matches_encoder(height, width):
    enc = ImageEncoder(vocab_size=3)
    with torch.no_grad():
        out = enc(torch.zeros(1, 3, height, width, dtype=torch.uint8))
    assert tuple(out.shape[2:]) == conv_output_size(height, width)


def test_image_encoder_scales_uint8_and_rejects_float():
    torch.manual_seed(0)
    enc = ImageEncoder(vocab_size=5)
    img = torch.randint(0, 256, (2, 3, 60, 108), dtype=torch.uint8)
    out = enc(img)
    assert out.shape == (2, 5, 2, 5)
    # model-side /255: same as running the conv stack on the scaled float image
    x = img.float() / 255
    ref = enc.conv3(torch.relu(enc.conv2(torch.relu(enc.conv1(x)))))
    torch.testing.assert_close(out, ref)
    with pytest.raises(TypeError):
        enc(img.float())


def test_bag_of_words():
    enc = TextEncoder(vocab_size=5, sentence=False)
    tokens = torch.tensor([[1, 3, 3, 0], [5, 0, 0, 0], [0, 0, 0, 0]])
    bow, sent = enc(tokens)
    assert sent is None
    assert list(enc.parameters()) == []
    expected = torch.tensor([[1, 0, 1, 0, 0], [0, 0, 0, 0, 1], [0, 0, 0, 0, 0]], dtype=torch.float32)
    torch.testing.assert_close(bow, expected)


def test_sentence_uses_last_non_pad_step():
    torch.manual_seed(0)
    enc = TextEncoder(vocab_size=6, embed_dim=8, gru=8)
    padded = torch.tensor([[2, 4, 6, 0, 0], [3, 0, 0, 0, 0], [0, 0, 0, 0, 0]])
    _, sent = enc(padded)
    assert sent.shape == (3, 6)
    assert torch.all(sent >= 0)  # ReLU
    for row, length in ((0, 3), (1, 1)):
        _, alone = enc(padded[row : row + 1, :length])
        torch.testing.assert_close(sent[row : row + 1], alone)
    # all-pad row: finite and equal to ReLU of the linear bias (h = 0)
    torch.testing.assert_close(sent[2], torch.relu(enc.linear.bias))
    sent.sum().backward()
    assert torch.isfinite(enc.gru.weight_ih_l0.grad).all()


def test_channels_last_gives_the_plain_layout_results_forward_and_backward():
    """The encoder runs NHWC (channels_last, issue 14); outputs and gradients equal the plain NCHW convolutions
    on contiguous copies of the same weights within float tolerance, and the output is an ordinary NCHW tensor."""
    import torch.nn.functional as F

    torch.manual_seed(0)
    enc = ImageEncoder(vocab_size=7)
    assert enc.conv1.weight.is_contiguous(memory_format=torch.channels_last)
    img = torch.randint(0, 256, (3, 3, 84, 150), dtype=torch.uint8)
    out = enc(img)
    assert out.is_contiguous() and out.shape == (3, 7, 4, 8)
    weights = [(c.weight.detach().contiguous().requires_grad_(), c.bias, c.stride) for c in (enc.conv1, enc.conv2)]
    x = img.float() / 255
    for w, b, s in weights:
        x = torch.relu(F.conv2d(x, w, b.detach(), s))
    w3 = enc.conv3.weight.detach().contiguous().requires_grad_()
    ref = F.conv2d(x, w3, enc.conv3.bias.detach(), enc.conv3.stride)
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
    out.square().sum().backward()
    ref.square().sum().backward()
    torch.testing.assert_close(enc.conv3.weight.grad, w3.grad, rtol=1e-4, atol=1e-5)
    torch.testing.assert_close(enc.conv1.weight.grad, weights[0][0].grad, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("stored", ["nchw", "hwc"])
def test_conv1_on_pixel_blocks_equals_conv1_forward_and_backward(stored):
    """conv1 computed on 4×4 pixel blocks (the update's large batches) equals the plain conv1 within float
    tolerance, outputs and gradients, for a width that is not a multiple of 4 and for frames stored either way."""
    torch.manual_seed(0)
    plain, blocks = ImageEncoder(vocab_size=7), ImageEncoder(vocab_size=7)
    blocks.load_state_dict(plain.state_dict())
    plain.blocks_from, blocks.blocks_from = None, (1, 1)
    img = torch.randint(0, 256, (3, 3, 84, 150), dtype=torch.uint8)
    if stored == "hwc":
        img = img.contiguous(memory_format=torch.channels_last)
    out, ref = blocks(img), plain(img)
    torch.testing.assert_close(out, ref, rtol=1e-5, atol=1e-5)
    out.square().sum().backward()
    ref.square().sum().backward()
    for a, b in zip(blocks.parameters(), plain.parameters()):
        torch.testing.assert_close(a.grad, b.grad, rtol=1e-4, atol=1e-5)


def test_conv1_runs_on_blocks_for_large_batches_of_large_frames_only():
    enc = ImageEncoder(vocab_size=3)
    big, small = torch.zeros(64, 3, 168, 300, dtype=torch.uint8), torch.zeros(8, 3, 168, 300, dtype=torch.uint8)
    assert enc._on_blocks(big) and not enc._on_blocks(small)
    assert not enc._on_blocks(torch.zeros(1024, 3, 84, 150, dtype=torch.uint8))


def test_a_large_batch_encodes_each_distinct_instruction_once_with_the_same_values_and_gradients():
    """The PPO update's T·B rows repeat each episode's instruction: the GRU runs on the distinct rows only, and
    the sentence embeddings and gradients are those of encoding every row."""
    torch.manual_seed(0)
    enc = TextEncoder(vocab_size=12)
    distinct = torch.randint(0, 13, (9, 6))
    distinct[:, 0] = torch.arange(1, 10)  # 9 different instructions
    tokens = distinct[torch.randint(0, 9, (256,))]
    seen = []
    enc.gru.register_forward_hook(lambda module, args, out: seen.append(args[0].shape[0]))
    bow, sent = enc(tokens)
    assert seen == [9]
    weights = torch.randn_like(sent)
    grads = torch.autograd.grad((sent * weights).sum(), list(enc.parameters()), allow_unused=True)
    ref = enc.sentence_embedding(tokens)  # every row through the GRU
    ref_grads = torch.autograd.grad((ref * weights).sum(), list(enc.parameters()), allow_unused=True)
    torch.testing.assert_close(sent, ref)
    for got, want in zip(grads, ref_grads):
        if want is not None:
            torch.testing.assert_close(got, want, rtol=1e-4, atol=1e-6)
    assert torch.equal(bow, enc.bag_of_words(tokens))


def test_the_mean_readout_reads_every_word_and_the_default_reads_the_last():
    """`ModelConfig.sentence_readout` (issue 34): 'mean' gives the Linear the mean of the GRU's outputs over the
    words (pad steps excluded); 'last', the default, its output after the last word."""
    torch.manual_seed(0)
    last = TextEncoder(vocab_size=6, embed_dim=8, gru=8)
    mean = TextEncoder(vocab_size=6, embed_dim=8, gru=8, readout="mean")
    mean.load_state_dict(last.state_dict())  # the same parameters: only the readout differs
    padded = torch.tensor([[2, 4, 6, 0, 0], [3, 0, 0, 0, 0], [0, 0, 0, 0, 0]])
    out = last.gru(last.embedding(padded))[0]
    expected = torch.relu(last.linear(torch.stack([out[0, :3].mean(0), out[1, 0], torch.zeros(8)])))
    torch.testing.assert_close(mean(padded)[1], expected)
    torch.testing.assert_close(last(padded)[1][:2], torch.relu(last.linear(torch.stack([out[0, 2], out[1, 0]]))))
    assert not torch.allclose(mean(padded)[1][0], last(padded)[1][0])  # a 3-word row: the two readouts differ
    mean.unrolled = True  # the packed trainer's GRU (vmap): the same readout
    torch.testing.assert_close(mean(padded)[1], expected, rtol=1e-5, atol=1e-6)


def test_the_softplus_activation_keeps_every_channel_alive_and_the_default_is_relu():
    """`ModelConfig.sentence_activation` (issue 34): 'softplus' in place of the paper's ReLU on x_sent's Linear, so
    that a channel whose pre-activation is negative for every sentence still passes a gradient."""
    torch.manual_seed(0)
    relu = TextEncoder(vocab_size=6, embed_dim=8, gru=8)
    soft = TextEncoder(vocab_size=6, embed_dim=8, gru=8, activation="softplus")
    soft.load_state_dict(relu.state_dict())
    with torch.no_grad():  # one dead channel: its pre-activation is negative for every sentence
        relu.linear.bias[3] = soft.linear.bias[3] = -100.0
    tokens = torch.tensor([[2, 4, 6, 0], [3, 1, 0, 0]])
    h = relu.gru(relu.embedding(tokens))[0][torch.arange(2), torch.tensor([2, 1])]
    torch.testing.assert_close(relu(tokens)[1], torch.relu(relu.linear(h)))
    torch.testing.assert_close(soft(tokens)[1], torch.nn.functional.softplus(soft.linear(h)))
    for enc in (relu, soft):
        enc(tokens)[1][:, 3].sum().backward()
    assert relu.linear.bias.grad[3] == 0 and soft.linear.bias.grad[3] > 0  # only softplus can bring it back


def test_every_declared_activation_has_its_function_and_another_name_is_refused():
    from emml.config.model import ACTIVATIONS
    from emml.models.baselines import AnswerHead
    from emml.models.encoders import ACTIVATION_FUNCTIONS, activation_function

    assert tuple(ACTIVATION_FUNCTIONS) == ACTIVATIONS
    z = torch.tensor([-2.0, 0.5])
    torch.testing.assert_close(activation_function("relu")(z), torch.relu(z))
    torch.testing.assert_close(activation_function("softplus")(z), torch.nn.functional.softplus(z))
    with pytest.raises(ValueError, match="activation='tanh' is not allowed; choose one of 'relu', 'softplus'"):
        TextEncoder(vocab_size=6, activation="tanh")
    head = AnswerHead(4, 3)
    torch.testing.assert_close(
        head.use("softplus")(torch.ones(1, 4)), torch.nn.functional.softplus(head.linear(torch.ones(1, 4)))
    )
    with pytest.raises(ValueError, match="answer_activation='tanh' is not allowed"):
        head.use("tanh")

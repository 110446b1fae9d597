"""BitDropout: exact keep probabilities from the fewest random bits."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elicit_jax.policy.dropout import BitDropout, keep_bits, keep_mask


@pytest.mark.parametrize(
    ("keep", "bits"),
    [(0.5, 1), (0.25, 2), (0.75, 2), (0.625, 4), (0.1875, 4), (1 / 256, 8), (3 / 65536, 16)],
)
def test_keep_bits_is_the_fewest_exact_width(keep, bits):
    assert keep_bits(keep) == bits


@pytest.mark.parametrize("keep", [0.9, 0.1, 1 / 3])
def test_keep_bits_none_when_no_width_is_exact(keep):
    assert keep_bits(keep) is None


def test_half_keep_uses_one_bit_per_entry_lowest_bit_first():
    key = jax.random.key(3)
    mask = np.asarray(keep_mask(key, 0.5, (5, 40)))  # 200 entries -> 7 words
    words = np.asarray(jax.random.bits(key, (7,), jnp.uint32))
    bit = np.array([(int(words[i // 32]) >> (i % 32)) & 1 for i in range(200)])
    np.testing.assert_array_equal(mask.reshape(-1), bit == 0)


def test_quarter_keep_uses_two_bit_fields():
    key = jax.random.key(4)
    mask = np.asarray(keep_mask(key, 0.25, (33,)))  # 33 entries -> 3 words of 16 fields
    words = np.asarray(jax.random.bits(key, (3,), jnp.uint32))
    field = np.array([(int(words[i // 16]) >> (2 * (i % 16))) & 3 for i in range(33)])
    np.testing.assert_array_equal(mask, field < 1)


@pytest.mark.parametrize("keep", [0.5, 0.75, 0.9])
def test_keep_rate_and_independence(keep):
    mask = np.asarray(keep_mask(jax.random.key(0), keep, (400, 500)), np.float64)
    n = mask.size
    assert abs(mask.mean() - keep) < 5 * np.sqrt(keep * (1 - keep) / n)
    flat = mask.reshape(-1)
    for lag in (1, 2, 31, 32, 33):  # neighbours within and across random words
        corr = np.corrcoef(flat[:-lag], flat[lag:])[0, 1]
        assert abs(corr) < 5 / np.sqrt(n)


def test_bit_dropout_scales_kept_and_zeroes_dropped():
    x = jnp.arange(1.0, 201.0).reshape(4, 50)
    layer = BitDropout(0.5)
    assert layer.apply({}, x, deterministic=True) is x
    y = np.asarray(layer.apply({}, x, deterministic=False, rngs={"dropout": jax.random.key(1)}))
    kept = y != 0
    np.testing.assert_allclose(y[kept], 2.0 * np.asarray(x)[kept])
    assert 60 < kept.sum() < 140
    assert np.all(np.asarray(BitDropout(1.0).apply({}, x, deterministic=False)) == 0)

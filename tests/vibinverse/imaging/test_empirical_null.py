"""The recording's own null: pooled tail, exponential tail of the per-frequency maxima, frame-wide lines."""

import math

import numpy as np

from vibinverse.imaging.empirical_null import FRAME_WIDE_MEDIAN, Z_EDGES, EmpiricalNull, z_counts
from vibinverse.imaging.whitening import corrected


def null_of(z, candidates=()):
    return EmpiricalNull.from_counts(z_counts(z), z.max(axis=0), np.asarray(candidates, dtype=np.int64))


def test_counts_hold_every_value_in_its_bin():
    rng = np.random.default_rng(0)
    z = rng.exponential(size=(300, 7)) * 10
    counts = z_counts(z)
    assert counts.shape == (7, Z_EDGES.size) and (counts.sum(axis=1) == 300).all()
    k = 3
    expected = np.histogram(z[:, k], bins=np.r_[Z_EDGES, np.inf])[0]
    assert (counts[k] == expected).all()


def test_pooled_tail_of_white_noise_is_the_exponential():
    rng = np.random.default_rng(1)
    null = null_of(rng.exponential(size=(20000, 100)))
    for z in (1.0, 2.0, 4.0, 8.0):
        assert abs(math.exp(null.log_tail(np.array(z))) / math.exp(-z) - 1) < 0.15
    assert null.log_tail(np.array(40.0)) == -np.inf  # never seen: no evidence, the white tail decides


def test_line_probability_is_conservative_on_white_noise():
    """400 data sets of 300 pixels x 64 frequencies of white noise: the share whose smallest
    corrected probability is below 0.1 is at most 0.1 (plus three standard errors) and not zero
    (the test still has power)."""
    rng = np.random.default_rng(2)
    n, level = 400, 0.1
    hits = 0
    for _ in range(n):
        z = rng.exponential(size=(300, 64))
        hits += null_of(z).line_probability(z.max(axis=0)).min() < level
    se = math.sqrt(level * (1 - level) / n)
    assert 0 < hits / n < level + 3 * se, hits / n


def test_heavy_tails_break_the_white_null_and_the_empirical_one_holds():
    """Pixels whose noise power varies (a log-normal scale per pixel, as codec blocks make): the
    white-noise false-alarm probability of the frame's maxima lies (most data sets 'detect'
    something at 0.05); the larger of it and the empirical one stays within the binomial bound."""
    rng = np.random.default_rng(3)
    n, level, m, p = 200, 0.05, 64, 400
    white = combined = 0
    for _ in range(n):
        scale = rng.lognormal(0.0, 0.6, size=(p, 1))
        z = rng.exponential(size=(p, m)) * scale
        top = z.max(axis=0)
        theory = corrected(-top, m * p)  # ln P(Exp(1) > z) = -z
        white += theory.min() < level
        combined += np.maximum(theory, null_of(z).line_probability(top)).min() < level
    se = math.sqrt(level * (1 - level) / n)
    assert white / n > 0.5
    assert combined / n < level + 3 * se, combined / n


def test_candidates_are_left_out_of_the_null():
    rng = np.random.default_rng(4)
    z = rng.exponential(size=(5000, 80))
    z[:, 40] += 500.0  # a line in every pixel
    with_line = null_of(z)
    without = null_of(z, candidates=[40])
    assert math.exp(with_line.log_tail(np.array(100.0))) > 0.01  # the line's powers make the tail
    assert without.log_tail(np.array(100.0)) == -np.inf


def test_a_line_in_most_of_the_frame_is_frame_wide():
    rng = np.random.default_rng(5)
    z = rng.exponential(size=(4000, 50))
    z[:3000, 10] *= 20.0
    null = null_of(z)
    assert null.frame_wide(10) and not null.frame_wide(11)
    assert null.frame_fraction[10] > 0.5 and null.frame_median[10] > FRAME_WIDE_MEDIAN
    assert null.frame_fraction[11] < 0.2  # P(Exp(1) >= 2) = 0.135


def test_candidates_everywhere_make_the_null_of_every_frequency():
    """A comb of lines on most frequencies leaves too few off them: the null is taken from all,
    which the comb widens (conservative), instead of falling back to white noise."""
    rng = np.random.default_rng(7)
    z = rng.exponential(size=(2000, 40))
    comb = np.arange(0, 40, 2)
    z[:, comb] += rng.exponential(60.0, size=(2000, comb.size))
    null = null_of(z, candidates=comb)
    assert null.tail is not None and null.tail[0] > 50  # the threshold sits among the comb's maxima
    white = corrected(-z.max(axis=0), 40 * 2000)
    assert (white[comb] < 1e-3).all() and (null.line_probability(z.max(axis=0)[comb]) > 1e-3).mean() > 0.5


def test_too_few_frequencies_give_no_tail_and_no_evidence():
    rng = np.random.default_rng(6)
    z = rng.exponential(size=(100, 10))
    null = null_of(z)
    assert null.tail is None and (null.line_probability(np.array([1.0, 100.0])) == 0).all()

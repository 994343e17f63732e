"""Per-episode input schedules (drake_abs.policy.controls): uniform random inputs, a sinusoidal
gait and a train of pushes are what their docstrings say (range, formula, seeding by the
episode's key, a longer schedule continues a shorter one), and episode seeds depend on the
episode alone."""

from __future__ import annotations

import numpy as np
import pytest

from drake_abs.policy.controls import episode_seed, push_inputs, sinusoid_inputs, uniform_inputs


def test_episode_seeds_are_fixed_distinct_32_bit_integers():
    seeds = [episode_seed(7, e) for e in range(50)]
    assert len(set(seeds)) == 50 and all(0 <= s < 2**32 for s in seeds)
    assert seeds == [episode_seed(7, e) for e in range(50)]
    assert episode_seed(8, 0) != seeds[0]
    with pytest.raises(ValueError, match="episode"):
        episode_seed(7, -1)


def test_uniform_inputs_in_range_seeded_and_continued():
    low, high = np.array([-200.0, -1.0, 0.0]), np.array([200.0, 1.0, 0.5])
    u = uniform_inputs(50, low, high, seed=[3, 11])
    assert u.shape == (50, 3) and np.all(u >= low) and np.all(u <= high)
    assert np.unique(u[:, 0]).size == 50  # a new draw every step
    np.testing.assert_array_equal(u, uniform_inputs(50, low, high, seed=[3, 11]))
    assert not np.array_equal(u, uniform_inputs(50, low, high, seed=[3, 12]))
    np.testing.assert_array_equal(uniform_inputs(80, low, high, seed=[3, 11])[:50], u)
    # row t is the generator's t-th draw of nu values
    rng = np.random.default_rng([3, 11])
    np.testing.assert_array_equal(u[:5], [rng.uniform(low, high) for _ in range(5)])
    assert uniform_inputs(4, -12.0, 12.0, seed=0).shape == (4, 1)
    with pytest.raises(ValueError, match="low must be <= high"):
        uniform_inputs(4, 1.0, -1.0, seed=0)
    with pytest.raises(ValueError, match="seed"):
        uniform_inputs(4, -1.0, 1.0, seed="a")


def test_sinusoid_inputs_are_a_gait_with_seeded_phases():
    amplitude, f, h = np.array([60.0, 90.0]), 2.5, 0.01
    u = sinusoid_inputs(200, amplitude, f, h, seed=[1, 2], offset=5.0)
    phases = np.random.default_rng([1, 2]).uniform(0.0, 2 * np.pi, 2)
    t = np.arange(200)[:, None]
    np.testing.assert_allclose(u, 5.0 + amplitude * np.sin(2 * np.pi * f * t * h + phases),
                               rtol=0, atol=1e-12)  # fmt: skip
    # one period is 1 / f = 40 steps
    np.testing.assert_allclose(u[40:], u[:-40], rtol=0, atol=1e-9)
    assert np.all(np.abs(u - 5.0) <= amplitude)
    assert not np.array_equal(u, sinusoid_inputs(200, amplitude, f, h, seed=[1, 3], offset=5.0))
    with pytest.raises(ValueError, match="time_step"):
        sinusoid_inputs(10, amplitude, f, 0.0, seed=0)


def test_push_inputs_are_pulses_and_pauses():
    u = push_inputs(130, 12.0, seed=[0, 5], on=30, off=20)
    assert u.shape == (130, 1) and np.all(np.abs(u) <= 12.0)
    np.testing.assert_array_equal(u[30:50], 0.0)  # the pause after the first pulse
    np.testing.assert_array_equal(u[80:100], 0.0)
    assert u[0, 0] == 0.0 and np.all(u[1:30] != 0.0)  # sin^2 from 0
    amplitudes = np.random.default_rng([0, 5]).uniform(-12.0, 12.0, 64)
    s = np.arange(30)
    np.testing.assert_allclose(u[50:80, 0], amplitudes[1] * np.sin(np.pi * s / 30) ** 2,
                               rtol=0, atol=1e-12)  # fmt: skip
    with pytest.raises(ValueError, match="on"):
        push_inputs(10, 12.0, seed=0, on=0)

"""pattern.check_omega: the one validator of the fold parameter, used by both forward models."""

import numpy as np
import pytest

import rffqm_nlp as rq
from rffqm_nlp.model import marching
from rffqm_nlp.model import numpy_model
from rffqm_nlp.model.pattern import check_omega, motion_omegas


def test_check_omega_keeps_scalars_and_1d_arrays():
    assert check_omega(np.pi).shape == ()
    assert float(check_omega(-np.pi)) == -np.pi
    np.testing.assert_array_equal(check_omega([0.0, 1.0, -3.0]), [0.0, 1.0, -3.0])


@pytest.mark.parametrize("bad, words", [
    (np.pi + 1e-9, "[-pi, pi]"), (np.nan, "[-pi, pi]"), (-np.inf, "[-pi, pi]"),
    ([0.1, 4.0], "got 4.0"), ([[0.1]], "shape (1, 1)"), ("wide", "got str"),
    ([], "shape (0,)"), (None, "got NoneType"), (True, "got bool"), ({"a": 1}, "got dict"),
    ([[0.1], [0.1, 0.2]], "ragged")])
def test_check_omega_refuses_in_one_line_naming_the_argument(bad, words):
    with pytest.raises(rq.InputError) as exc:
        check_omega(bad, name="--omega")
    msg = str(exc.value)
    assert msg.startswith("--omega must") and words in msg and "\n" not in msg


@pytest.mark.parametrize("model", [marching, numpy_model])
def test_both_forward_models_validate_omega_with_it(model):
    pat = numpy_model.march(rq.miura_boundary(2, 2))
    for bad in (np.pi + 1e-6, np.nan, [[0.1]], "x", None):
        with pytest.raises(rq.InputError, match="^omega must"):
            model.fold(pat, bad)
        with pytest.raises(rq.InputError, match="^omega must"):
            model.fold_angles(pat, bad)


def test_motion_omegas_run_from_flat_and_check_the_count():
    np.testing.assert_allclose(motion_omegas(-2.0, 5), np.linspace(0.0, -2.0, 5), rtol=0)
    assert motion_omegas(1.0, 1).tolist() == [0.0]
    for frames, minimum in ((1, 2), (0, 1), (2.0, 1), (True, 1), ("3", 1), (10**12, 1),
                            (-1, 1), (None, 1)):
        with pytest.raises(rq.InputError,
                           match=rf"^--frames must be a whole number in \[{minimum}, 100000\]"):
            motion_omegas(1.0, frames, minimum=minimum, name="--frames")
    with pytest.raises(rq.InputError, match="omega_end must lie in"):
        motion_omegas(4.0, 3)


# --------------------------------------------------------------------------- Pattern
def marched():
    return numpy_model.march(rq.miura_boundary(2, 3))


FIELDS = ("alpha", "beta", "sigma", "lh", "lv", "mu", "X")


def with_field(pat, name, change):
    arrays = {k: np.array(getattr(pat, k)) for k in FIELDS}
    arrays[name] = change(arrays[name])
    return arrays


@pytest.mark.parametrize("name, change, words", [
    ("lh", lambda a: a * np.nan, "Pattern lh must be horizontal side lengths (N+1, M), finite "
                                 "and positive, got nan at index (0, 0)"),
    ("X", lambda a: np.where(a == 0, np.inf, a), "Pattern X must be finite flat positions"),
    ("alpha", lambda a: a[:1], "Pattern alpha must have shape (N+1, M+1) with N, M >= 1"),
    ("beta", lambda a: a[:, :2], "Pattern beta must have shape (3, 4) for the 2 x 3 panels"),
    ("mu", lambda a: "many", "Pattern mu must be finite multipliers mu_abc (N, M), got the "
                             "string 'many'"),
    ("alpha", lambda a: a + 4.0, "Pattern alpha must lie in [0, pi], got"),
    ("sigma", lambda a: a * 0.5, "Pattern sigma must be +1 or -1, got -0.5 at index (0, 0)"),
    ("lv", lambda a: -a, "Pattern lv must be positive lengths, got -1 at index (0, 0)"),
    ("X", lambda a: a.astype(complex), "Pattern X must be finite flat positions (N+1, M+1, 3), "
                                       "got complex numbers"),
    ("lh", lambda a: [[1.0], [1.0, 2.0]], "Pattern lh must be horizontal side lengths (N+1, M), "
                                          "finite and positive, got a ragged or mixed list"),
])
def test_pattern_refuses_arrays_that_no_march_makes(name, change, words):
    """A Pattern is only made of finite numbers of its shapes, angles in [0, pi], signs +-1
    and positive sides; the first bad entry is named in one line."""
    with pytest.raises(rq.InputError) as exc:
        rq.Pattern(**with_field(marched(), name, change))
    assert str(exc.value).startswith(words), str(exc.value)


def test_pattern_keeps_what_marching_makes_and_copies_it_read_only():
    pat = marched()
    arrays = {k: np.array(getattr(pat, k)) for k in FIELDS}
    again = rq.Pattern(**arrays)
    arrays["lh"][0, 0] = 99.0                          # the caller's array is not the Pattern's
    for k in FIELDS:
        np.testing.assert_array_equal(getattr(again, k), getattr(pat, k))
        assert not getattr(again, k).flags.writeable
    assert rq.Pattern.from_dict(pat.to_dict()).N == 2
    with pytest.raises(rq.InputError, match="^a pattern must be a table of alpha, beta"):
        rq.Pattern.from_dict(["alpha"])
    with pytest.raises(rq.InputError, match="missing the field 'mu'"):
        rq.Pattern.from_dict({k: v for k, v in pat.to_dict().items() if k != "mu"})


def test_single_fold_angles_patterns_and_memory_are_checked(monkeypatch):
    from rffqm_nlp.model import pattern

    assert pattern.check_fold_angle(np.float64(0.5)) == 0.5
    with pytest.raises(rq.InputError, match=r"^omega_max must be a single number in \[-pi, "
                                            r"pi\], got a list of 2 numbers"):
        pattern.check_fold_angle([0.1, 0.2], "omega_max")
    with pytest.raises(rq.InputError, match="^pattern must be a crease pattern .*got None"):
        pattern.check_pattern(None)
    # a march or a fold whose arrays exceed the memory left is refused before any work
    monkeypatch.setattr(rq.memory, "available", lambda: 50_000_000)
    with pytest.raises(rq.InputError, match="a march of 1000 x 1000 panels needs about 1 GB; "
                                            "this machine has 0.05 GB available"):
        numpy_model.march(rq.miura_boundary(1000, 1000))
    pat = marched()
    for fold in (numpy_model.fold, marching.fold):
        with pytest.raises(rq.InputError, match="50000 folded states of 2 x 3 panels"):
            fold(pat, np.zeros(50_000))
    assert numpy_model.fold(pat, np.zeros(3)).shape == (3, 3, 4, 3)    # small: no lookup

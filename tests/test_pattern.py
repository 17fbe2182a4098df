"""pattern.check_omega: the one validator of the fold parameter, used by both forward models."""

import numpy as np
import pytest

import rffqm_nlp as rq
from rffqm_nlp import marching, numpy_model
from rffqm_nlp.pattern import check_omega, motion_omegas


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
    for frames, minimum in ((1, 2), (0, 1), (2.0, 1), (True, 1), ("3", 1)):
        with pytest.raises(rq.InputError, match=rf"^--frames must be an integer >= {minimum}"):
            motion_omegas(1.0, frames, minimum=minimum, name="--frames")
    with pytest.raises(rq.InputError, match="omega_end must lie in"):
        motion_omegas(4.0, 3)

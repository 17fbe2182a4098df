"""FOLD 1.2 files: round trips, numbering, frames, validation of broken files."""

from __future__ import annotations

import copy
import json
from collections import Counter

import numpy as np
import pytest
from crease_patterns import OMEGA, PATTERNS, expected_kinds, make_pattern, n_edges

import rffqm_nlp as rq
from rffqm_nlp.io import foldfile
from rffqm_nlp.model import marching
from rffqm_nlp.errors import InputError


@pytest.fixture(scope="module", params=PATTERNS)
def pat(request):
    return make_pattern(request.param)


# --------------------------------------------------------------------------- FOLD
def test_fold_round_trip(pat, tmp_path):
    path = foldfile.write_fold(tmp_path / "p.fold", pat, OMEGA, frames=4,
                          metadata={"target": "sphere_cap", "rms": np.float64(0.5)})
    back, omega, meta = foldfile.read_fold(path)
    assert omega == OMEGA
    assert meta == {"target": "sphere_cap", "rms": 0.5}
    for name in ("alpha", "beta", "sigma", "lh", "lv", "mu", "X"):
        np.testing.assert_array_equal(getattr(back, name), getattr(pat, name))
    d = json.loads(path.read_text())
    assert d["file_spec"] == 1.2 and d["file_creator"] == "rffqm-nlp"
    assert d["frame_classes"] == ["creasePattern"] and d["frame_attributes"] == ["2D"]
    assert d["edges_vertices"] == foldfile.fold_dict(back, omega)["edges_vertices"]
    assert len(d["vertices_coords"]) == (pat.N + 1) * (pat.M + 1)
    assert all(len(p) == 2 for p in d["vertices_coords"])
    assert len(d["faces_vertices"]) == pat.N * pat.M


def test_fold_edges_match_fold_angles(pat):
    d = foldfile.fold_dict(pat, OMEGA)
    N, M = pat.N, pat.M
    assert len(d["edges_vertices"]) == n_edges(pat)
    assert Counter(d["edges_assignment"]) == expected_kinds(pat)
    gh, gv = marching.fold_angles(pat, OMEGA)
    angles = np.degrees(np.concatenate([gh.ravel(), gv.ravel()]))
    np.testing.assert_allclose(d["edges_foldAngle"], angles, atol=1e-12)
    # The first horizontal edge joins vertex (1, 1) and (1, 2); the first vertical one
    # joins (1, 1) and (2, 1).
    assert d["edges_vertices"][0] == [0, 1]
    assert d["edges_vertices"][(N + 1) * M] == [0, M + 1]
    for kind, ang in zip(d["edges_assignment"], d["edges_foldAngle"]):
        assert kind == "B" or (kind == "V") == (ang > 0)


def test_fold_frames_equal_marching_fold(pat):
    omegas = np.array([-0.4, 0.0, 0.7, np.pi])
    d = foldfile.fold_dict(pat, OMEGA, frames=omegas)
    assert len(d["file_frames"]) == 4
    for w, frame in zip(omegas, d["file_frames"]):
        assert frame["frame_classes"] == ["foldedForm"]
        assert frame["frame_parent"] == 0 and frame["frame_inherit"] is True
        assert frame["rffqm:omega"] == w
        Y = marching.fold(pat, w).reshape(-1, 3)
        np.testing.assert_allclose(frame["vertices_coords"], Y, rtol=0, atol=1e-12)
        assert Counter(frame["edges_assignment"]) == expected_kinds(pat, w or OMEGA)
    assert foldfile.validate_fold(d) == []
    counted = foldfile.fold_dict(pat, OMEGA, frames=5)["file_frames"]
    np.testing.assert_allclose([f["rffqm:omega"] for f in counted], np.linspace(0, OMEGA, 5))


def test_fold_at_zero_uses_positive_branch(pat):
    flat = foldfile.fold_dict(pat, 0.0)
    assert Counter(flat["edges_assignment"]) == expected_kinds(pat)
    assert not np.any(flat["edges_foldAngle"])
    assert foldfile.validate_fold(flat) == []


def test_validate_written_files(pat, tmp_path):
    path = foldfile.write_fold(tmp_path / "p.fold", pat, OMEGA, frames=3)
    assert foldfile.validate_fold(json.loads(path.read_text())) == []


def _corrupt(d: dict, how: str) -> dict:
    d = copy.deepcopy(d)
    if how == "index":
        d["edges_vertices"][3][1] = len(d["vertices_coords"]) + 7
    elif how == "face_index":
        d["faces_vertices"][0][0] = -1
    elif how == "clockwise":
        d["faces_vertices"][2] = d["faces_vertices"][2][::-1]
    elif how == "missing":
        del d["edges_vertices"]
    elif how == "assignment":
        d["edges_assignment"][0] = "X"
    elif how == "angle_sign":
        k = d["edges_assignment"].index("V")
        d["edges_foldAngle"][k] = -30.0
    elif how == "length":
        d["edges_assignment"].pop()
    elif how == "frame":
        d["file_frames"][1]["vertices_coords"].pop()
    elif how == "frame_angle":
        k = d["file_frames"][1]["edges_assignment"].index("M")
        d["file_frames"][1]["edges_foldAngle"][k] = 10.0
    elif how == "frame_nan":
        d["file_frames"][1]["vertices_coords"][2][1] = float("nan")
    elif how == "angle_nan":
        d["edges_foldAngle"][4] = float("inf")
    elif how == "huge_coord":
        d["vertices_coords"][1][0] = 10**400
    elif how == "string_coord":
        d["vertices_coords"][1][0] = "1.5"
    elif how == "string_index":
        d["edges_vertices"][0][1] = "1"
    elif how == "long_parent":
        d["file_frames"][0]["frame_parent"] = "Q" * 5000
    return d


@pytest.mark.parametrize("how, words", [
    ("index", "edges_vertices has indices"), ("face_index", "faces_vertices has indices"),
    ("clockwise", "face 2 is not counter-clockwise"), ("missing", "missing key"),
    ("assignment", "'X'"), ("angle_sign", "disagrees with assignment 'V'"),
    ("length", "one assignment per edge"), ("frame", "file_frames[1]: vertices_coords"),
    ("frame_angle", "file_frames[1]: edges_foldAngle disagrees with assignment 'M'"),
    ("frame_nan", "file_frames[1]: vertices_coords has non-finite coordinates"),
    ("angle_nan", "edges_foldAngle has non-finite angles"),
    ("huge_coord", "vertices_coords is not a rectangular array of numbers"),
    ("string_coord", "vertices_coords is not a rectangular array of numbers"),
    ("string_index", "edges_vertices is not a rectangular array of whole numbers"),
    ("long_parent", "file_frames[0]: frame_parent (a string of 5000 characters) is not")])
def test_validate_finds_problems(how, words):
    pat = marching.march(rq.miura_boundary(2, 3))
    problems = foldfile.validate_fold(_corrupt(foldfile.fold_dict(pat, OMEGA, frames=2), how))
    assert len(problems) == 1 and words in problems[0], problems
    assert "QQQQ" not in problems[0]


def test_validate_survives_garbage():
    assert foldfile.validate_fold([1, 2]) != []
    assert foldfile.validate_fold({"file_spec": 1.2, "vertices_coords": [[0, "a"], [1]]}) != []
    bad_faces = {"file_spec": 1.2, "vertices_coords": [[0, 0], [1, 0], [0, 1]],
                 "edges_vertices": [[0, 1]], "edges_assignment": [["B"]],
                 "faces_vertices": [[0, 1, "2"]]}
    assert len(foldfile.validate_fold(bad_faces)) == 2


def test_read_rejects_other_files(tmp_path):
    not_fold = tmp_path / "other.json"
    not_fold.write_text(json.dumps({"hello": "world"}))
    with pytest.raises(InputError, match="not a valid FOLD file"):
        foldfile.read_fold(not_fold)
    broken = tmp_path / "broken.fold"
    broken.write_text("{ not json")
    with pytest.raises(InputError, match="JSON"):
        foldfile.read_fold(broken)
    foreign = foldfile.fold_dict(marching.march(rq.miura_boundary(2, 2)), OMEGA)
    foreign = {k: v for k, v in foreign.items() if not k.startswith("rffqm:")}
    foreign["file_creator"] = "someone else"
    other = tmp_path / "foreign.fold"
    other.write_text(json.dumps(foreign))
    with pytest.raises(InputError, match="not one written by rffqm-nlp"):
        foldfile.read_fold(other)


def test_read_rejects_edited_coordinates(tmp_path):
    pat = marching.march(rq.miura_boundary(2, 2))
    d = foldfile.fold_dict(pat, OMEGA)
    d["vertices_coords"][4][0] += 1e-3
    path = tmp_path / "edited.fold"
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match="do not match"):
        foldfile.read_fold(path)


def test_reserved_metadata_and_bad_frames():
    pat = marching.march(rq.miura_boundary(2, 2))
    with pytest.raises(InputError, match="reserved"):
        foldfile.fold_dict(pat, OMEGA, metadata={"omega": 1})
    with pytest.raises(InputError, match="cannot be stored in JSON"):
        foldfile.fold_dict(pat, OMEGA, metadata={"when": object()})
    with pytest.raises(InputError, match="frames"):
        foldfile.fold_dict(pat, OMEGA, frames=0)


def test_read_re_marches_the_pattern_of_a_perturbed_design(tmp_path):
    """A written pattern of the CasADi model reads back (the NumPy model's re-march agrees);
    the same file with one interior angle moved by 1e-6 is refused."""
    pat = make_pattern("perturbed")
    path = foldfile.write_fold(tmp_path / "p.fold", pat, OMEGA)
    back, omega, _ = foldfile.read_fold(path)
    np.testing.assert_array_equal(back.alpha, pat.alpha)
    d = json.loads(path.read_text())
    d["rffqm:pattern"]["beta"][3][4] += 1e-6
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match=r"rffqm:pattern\.beta does not match its boundary "
                                         "data re-marched"):
        foldfile.read_fold(path)


def test_a_fold_file_with_huge_sides_round_trips(tmp_path):
    """Sides of 1e150: still finite doubles; written and read back whole."""
    pat = marching.march(rq.miura_boundary(2, 2, a=1e150, b=1e150))
    back, _, _ = foldfile.read_fold(foldfile.write_fold(tmp_path / "p.fold", pat, OMEGA,
                                                        frames=2))
    np.testing.assert_array_equal(back.X, pat.X)

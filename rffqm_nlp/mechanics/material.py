"""The sheet's material and the stiffness of the bars and hinges made from it (SI units).

* Membrane: each triangle of a panel (the diagonal cuts it in two, :mod:`.frame`) is a
  linear plane-stress constant-strain triangle of thickness t. Its strain is fixed by the
  elongations of its three bars, so its energy is a 3 x 3 quadratic form in them: the bars
  carry the exact membrane stiffness for any Poisson's ratio nu (independent bars of an
  N4B5 panel cannot: one diagonal gives no isotropic shear, Filipov et al., Int. J. Solids
  Struct. 2017, s.4).
* Panel bending: the hinge on a panel's diagonal of length D has the rotational stiffness
  k_B = 0.55 D_p (D / t)^(1/3), D_p = E t^3 / (12 (1 - nu^2)) (Filipov et al. 2017, s.4.3).
* Folding: a crease of length L has k_F = fold_stiffness * L.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from ..errors import InputError
from ..files import Key, check_value

#: Filipov et al.'s (2017) bending coefficient C_B of k_B = C_B D_p (D/t)^(1/3).
BENDING_COEFFICIENT = 0.55

_KEYS = {"E": Key("number", low=1e3, high=1e13, hint="(Pa)"),
         "nu": Key("number", low=-0.99, high=0.5, high_open=True),
         "thickness": Key("number", low=1e-7, high=1.0, hint="(m)"),
         "fold_stiffness": Key("number", low=0.0, high=1e9, hint="(N m/rad per m of crease)"),
         "density": Key("number", low=0.0, high=1e5, hint="(kg/m^3)")}


@dataclass(frozen=True)
class Material:
    """A sheet: Young's modulus ``E`` (Pa, 1e3 to 1e13), Poisson's ratio ``nu`` (in
    [-0.99, 0.5)), ``thickness`` (m, 1e-7 to 1), the fold hinges' stiffness per length of
    crease ``fold_stiffness`` (N m/rad per m, 0 to 1e9; 0 makes free hinges) and
    ``density`` (kg/m^3, 0 to 1e5). Every field is checked; :class:`InputError` names the
    first one out of range."""

    E: float
    nu: float
    thickness: float
    fold_stiffness: float = 0.0
    density: float = 0.0

    def __post_init__(self) -> None:
        for name, key in _KEYS.items():
            object.__setattr__(self, name, check_value(getattr(self, name), key, name))

    @property
    def plate_modulus(self) -> float:
        """The bending stiffness D_p = E t^3 / (12 (1 - nu^2)) (N m)."""
        return self.E * self.thickness ** 3 / (12 * (1 - self.nu ** 2))

    def with_fold_stiffness(self, fold_stiffness: float) -> "Material":
        """The same sheet with another fold stiffness (N m/rad per m)."""
        return Material(self.E, self.nu, self.thickness, fold_stiffness, self.density)

    @classmethod
    def named(cls, name: str) -> "Material":
        """A sheet of :data:`MATERIALS` by its name; :class:`InputError` for another."""
        check_value(name, Key("choice", choices=tuple(MATERIALS)), "material")
        return MATERIALS[name]


def _sheet(E: float, nu: float, thickness: float, density: float) -> Material:
    """A sheet whose creases are as stiff as 25 mm of the sheet bent: fold_stiffness
    = D_p / 0.025 m (an indicative value; measure a crease for a real one)."""
    plate = E * thickness ** 3 / (12 * (1 - nu ** 2))
    return Material(E, nu, thickness, plate / 0.025, density)


#: Indicative sheets (handbook values, not measurements): 160 g/m^2 paper, 0.4 mm card,
#: 0.5 mm polypropylene, 1 mm PET.
MATERIALS = {"paper": _sheet(4.0e9, 0.3, 0.2e-3, 800.0),
             "card": _sheet(3.0e9, 0.3, 0.4e-3, 700.0),
             "polypropylene": _sheet(1.5e9, 0.42, 0.5e-3, 905.0),
             "pet": _sheet(2.8e9, 0.38, 1.0e-3, 1380.0)}


def check_material(material: object) -> Material:
    """``material`` if it is a :class:`Material`, else :class:`InputError`."""
    if not isinstance(material, Material):
        raise InputError(f"material must be a rffqm_nlp.mechanics.Material (or one of "
                         f"{', '.join(MATERIALS)} by Material.named), got "
                         f"{type(material).__name__}")
    return material


def membrane_matrix(P: np.ndarray, triangles: np.ndarray, triangle_bars: np.ndarray,
                    n_bars: int, material: Material) -> sp.csr_matrix:
    """The membrane stiffness C (n_bars, n_bars) in N/m: the strain energy of the triangles
    is (1/2) e^T C e for bar elongations e (m). ``P`` (n_nodes, 3) in metres, ``triangles``
    and ``triangle_bars`` (n_triangles, 3) as in :class:`~.frame.Frame`."""
    x0, x1, x2 = (P[triangles[:, k]] for k in range(3))
    sides = np.stack([x1 - x0, x2 - x1, x0 - x2], axis=1)              # (T, 3, 3)
    lengths = np.linalg.norm(sides, axis=2)                            # (T, 3)
    normal = np.cross(sides[:, 0], -sides[:, 2])
    area = np.linalg.norm(normal, axis=1) / 2
    u = sides[:, 0] / lengths[:, :1]
    w = np.cross(normal / (2 * area[:, None]), u)
    c = np.einsum("tsk,tk->ts", sides, u) / lengths
    s = np.einsum("tsk,tk->ts", sides, w) / lengths
    # strain of side k along its direction: c^2 exx + s^2 eyy + c s gxy = T (exx, eyy, gxy)
    T = np.stack([c * c, s * s, c * s], axis=2)                       # (T, 3, 3)
    E, nu, t = material.E, material.nu, material.thickness
    D = E / (1 - nu ** 2) * np.array([[1, nu, 0], [nu, 1, 0], [0, 0, (1 - nu) / 2]])
    Tinv = np.linalg.inv(T) / lengths[:, None, :]                     # strains from elongations
    blocks = np.einsum("tji,jk,tkl->til", Tinv, D, Tinv) * (t * area)[:, None, None]
    rows = np.repeat(triangle_bars, 3, axis=1).ravel()
    cols = np.tile(triangle_bars, (1, 3)).ravel()
    return sp.csr_matrix((blocks.ravel(), (rows, cols)), shape=(n_bars, n_bars))


def bending_stiffness(diagonal_lengths: np.ndarray, material: Material) -> np.ndarray:
    """k_B (N m/rad) of the bending hinges on diagonals of these lengths (m) (module
    docstring)."""
    return (BENDING_COEFFICIENT * material.plate_modulus
            * np.cbrt(diagonal_lengths / material.thickness))

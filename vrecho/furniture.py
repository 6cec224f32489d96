"""Furniture: boxes in a room (tables, sofas, shelves, an open door's leaf) that reflect sound and
block the camera's view.

A :class:`Furniture` is an upright box, turned about the vertical: its footprint's centre, its
width (along its own x axis), depth and height, the height of its underside (0 for a box that
stands on the floor; a table top or a door leaf floats above it, its legs and hinges left out),
and its turn. Its faces (:meth:`Furniture.faces`) are wound as the room's boundary is, their
normals pointing out of the room's air, into the box.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .device import REACH_M
from .errors import check_field, check_keys, check_number, check_text, check_vector
from .materials import Material

SIZE_M = (0.01, 50.0)
"""Each side of a piece, and its underside's height, in metres: from 1 cm to what the largest room
holds (:data:`vrecho.scene.ROOM_SIZE_M`); its scene checks it stands wholly inside its own room."""


@dataclass(frozen=True)
class Furniture:
    """An upright box in the room.

    Parameters
    ----------
    name : str
        What it is ("table", "sofa", "shelf", "door leaf", ...).
    center : tuple of (float, float)
        Its footprint's centre [x, y], in metres.
    size : tuple of (float, float, float)
        Width, depth and height, in metres (each at least 1 cm).
    z0 : float
        The height of its underside above the floor, in metres (0: it stands on the floor).
    yaw_deg : float
        Its turn about the vertical, in degrees (its width along +x at 0).
    material : Material
        Its surfaces' absorption.

    Raises
    ------
    VrechoError
        For a size outside 1 cm to 50 m (:data:`SIZE_M`) or not finite, a ``z0`` outside 0 to
        50 m, a ``yaw_deg`` outside -360 to 360 or a ``center`` that is not two finite numbers.

    Examples
    --------
    >>> from vrecho.materials import Material
    >>> table = Furniture("table", (2.0, 1.5), (1.2, 0.8, 0.04), z0=0.72, material=Material("wood", (0.1,) * 7))
    >>> len(table.faces()), table.top_m
    (6, 0.76)
    """

    name: str
    center: tuple[float, float]
    size: tuple[float, float, float]
    z0: float = 0.0
    yaw_deg: float = 0.0
    material: Material = Material("wood", (0.15, 0.11, 0.1, 0.07, 0.06, 0.07, 0.07))

    def __post_init__(self):
        where = f"furniture {self.name!r}"
        size = check_vector(self.size, f"{where} size", 3, lo=SIZE_M[0], hi=SIZE_M[1])
        object.__setattr__(self, "z0", check_number(self.z0, f"{where} z0", lo=0.0, hi=SIZE_M[1]))
        object.__setattr__(self, "yaw_deg", check_number(self.yaw_deg, f"{where} yaw_deg", lo=-360.0, hi=360.0))
        object.__setattr__(self, "size", tuple(size.tolist()))
        object.__setattr__(self, "center", tuple(check_vector(self.center, f"{where} center", 2).tolist()))

    @property
    def top_m(self) -> float:
        """The height of its top above the floor, in metres."""
        return round(self.z0 + self.size[2], 9)

    def footprint(self) -> np.ndarray:
        """Its footprint's corners.

        Returns
        -------
        numpy.ndarray [shape=(4, 2)]
            [x, y] in metres, counter-clockwise seen from above.
        """
        c, s = np.cos(np.radians(self.yaw_deg)), np.sin(np.radians(self.yaw_deg))
        w, d = self.size[0] / 2, self.size[1] / 2
        local = np.array([[-w, -d], [w, -d], [w, d], [-w, d]])
        return np.asarray(self.center) + local @ np.array([[c, s], [-s, c]])

    @property
    def on_floor(self) -> bool:
        """Whether it stands on the floor (the floor then covers its underside)."""
        return self.z0 <= 1e-6

    def underside(self) -> np.ndarray:
        """Its underside, wound so that its normal points up into the box.

        Returns
        -------
        numpy.ndarray [shape=(4, 3)]
            The corners in metres.
        """
        return np.c_[self.footprint(), np.full(4, self.z0)]

    def faces(self) -> list[np.ndarray]:
        """Its faces, each wound so that its normal points into the box (out of the room's air).

        Returns
        -------
        list of numpy.ndarray [shape=(4, 3)]
            The four sides, the top, and the underside unless it stands on the floor (the floor
            covers it), in metres.
        """
        fp = self.footprint()
        lo, hi = self.z0, self.top_m
        out = []
        for i in range(4):
            a, b = fp[i], fp[(i + 1) % 4]
            # Seen from outside, a side runs a -> b counter-clockwise about the box: wound b -> a
            # its normal points inward.
            out.append(np.array([[b[0], b[1], lo], [a[0], a[1], lo], [a[0], a[1], hi], [b[0], b[1], hi]]))
        out.append(np.c_[fp[::-1], np.full(4, hi)])  # the top, its normal down into the box
        if not self.on_floor:
            out.append(self.underside())
        return out

    def contains(self, points: np.ndarray, *, margin_m: float = 0.0) -> np.ndarray:
        """Whether points lie inside the box, or within ``margin_m`` of it.

        Parameters
        ----------
        points : array_like [shape=(N, 3)]
            World positions, in metres.
        margin_m : float
            Grow the box by this much on every side, in metres (default 0).

        Returns
        -------
        numpy.ndarray [shape=(N,), dtype=bool]
        """
        p = np.atleast_2d(np.asarray(points, float))
        c, s = np.cos(np.radians(self.yaw_deg)), np.sin(np.radians(self.yaw_deg))
        rel = p[:, :2] - np.asarray(self.center)
        u, v = rel @ np.array([c, s]), rel @ np.array([-s, c])
        w, d = self.size[0] / 2 + margin_m, self.size[1] / 2 + margin_m
        return (np.abs(u) <= w) & (np.abs(v) <= d) & (p[:, 2] >= self.z0 - margin_m) & (p[:, 2] <= self.top_m + margin_m)

    def to_dict(self) -> dict:
        """Its JSON form.

        Returns
        -------
        dict
            ``name``, ``center``, ``size``, ``z0``, ``yaw_deg``, ``material``.
        """
        return {"name": self.name, "center": list(self.center), "size": list(self.size), "z0": self.z0,
                "yaw_deg": self.yaw_deg, "material": self.material.to_dict()}

    @classmethod
    def from_dict(cls, d, where: str) -> "Furniture":
        """A piece of furniture from its JSON form.

        Parameters
        ----------
        d : dict
            As :meth:`to_dict` writes it; ``z0`` and ``yaw_deg`` 0 and ``material`` wood if
            absent.
        where : str
            Where ``d`` sits in its file, named by errors.

        Returns
        -------
        Furniture
        """
        check_keys(d, ("name", "center", "size", "z0", "yaw_deg", "material"), where)
        name = check_text(check_field(d, "name", where, "furniture"), f"{where}.name")
        center = check_vector(check_field(d, "center", where), f"{where}.center", 2, lo=-REACH_M, hi=REACH_M)
        size = check_vector(check_field(d, "size", where), f"{where}.size", 3, lo=SIZE_M[0], hi=SIZE_M[1])
        z0 = check_number(check_field(d, "z0", where, 0.0), f"{where}.z0", lo=0.0, hi=SIZE_M[1])
        yaw = check_number(check_field(d, "yaw_deg", where, 0.0), f"{where}.yaw_deg", lo=-360.0, hi=360.0)
        material = check_field(d, "material", where, None)
        kwargs = {} if material is None else {"material": Material.from_dict(material, f"{where}.material")}
        return cls(name, tuple(center.tolist()), tuple(size.tolist()), z0, yaw, **kwargs)

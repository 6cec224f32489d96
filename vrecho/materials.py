"""Acoustic materials: energy absorption per octave band, as PROTOCOL.md draws them.

:data:`BANDS_HZ` are the bands of every coefficient in a scene; :data:`HEAVY_GLASS` and
:data:`WINDOW_GLASS` bound a glass pane's absorption, :data:`MIRROR` is glass on a rigid backing.
A :class:`Material` is named, checked on construction, and read from JSON or from
pyroomacoustics' database.
"""

from __future__ import annotations

from dataclasses import dataclass

from .errors import VrechoError, check_field, check_keys, check_number, check_text, check_vector

BANDS_HZ = (125, 250, 500, 1000, 2000, 4000, 8000)
"""Octave-band centres (Hz) of every absorption coefficient in a scene."""

HEAVY_GLASS = (0.18, 0.06, 0.04, 0.03, 0.02, 0.02, 0.02)
"""Heavy plate glass, per band of :data:`BANDS_HZ` (PROTOCOL.md)."""
WINDOW_GLASS = (0.35, 0.25, 0.18, 0.12, 0.07, 0.04, 0.04)
"""Ordinary window glass, per band."""
MIRROR = (0.03, 0.03, 0.03, 0.03, 0.02, 0.02, 0.02)
"""A mirror: glass on a rigid wall backing, per band."""


@dataclass(frozen=True)
class Material:
    """Acoustic material: energy absorption per octave band of :data:`BANDS_HZ`, and scattering.

    Parameters
    ----------
    name : str
    absorption : tuple of float
        Seven values in [0, 1], one per band; kept as a tuple of floats.
    scattering : float
        In [0, 1]; 0.1 by default.

    Raises
    ------
    VrechoError
        For any other ``absorption`` or ``scattering``.
    """

    name: str
    absorption: tuple[float, ...]
    scattering: float = 0.1

    def __post_init__(self):
        where = f"material {self.name!r}"  # one per band of BANDS_HZ
        a = check_vector(self.absorption, f"{where} absorption", len(BANDS_HZ), lo=0.0, hi=1.0)
        check_number(self.scattering, f"{where} scattering", lo=0.0, hi=1.0)
        object.__setattr__(self, "absorption", tuple(a.tolist()))

    @classmethod
    def from_database(cls, name: str, *, scattering: float = 0.1) -> "Material":
        """A material of pyroomacoustics' database, its bands padded to the seven of the protocol
        (repeating the last).

        Parameters
        ----------
        name : str
            A database entry, e.g. ``"brick_bare"``.
        scattering : float
            In [0, 1]; 0.1 by default.

        Returns
        -------
        Material

        Raises
        ------
        VrechoError
            If ``name`` is not in the database.
        """
        import pyroomacoustics as pra  # heavy (1.4 s): its database only where a material is named

        for entries in pra.materials_data["absorption"].values():
            if name in entries:
                coeffs = list(entries[name]["coeffs"])
                coeffs += [coeffs[-1]] * (len(BANDS_HZ) - len(coeffs))  # 6-band entries end at 4 kHz
                return cls(name, tuple(coeffs), scattering)
        raise VrechoError(f"material: {name!r} is not in pyroomacoustics' materials database")

    def to_dict(self) -> dict:
        """The material's JSON form.

        Returns
        -------
        dict
            ``name``, ``absorption`` (7 values), ``scattering``.
        """
        return {"name": self.name, "absorption": list(self.absorption), "scattering": self.scattering}

    @classmethod
    def from_dict(cls, d, where: str) -> "Material":
        """A material from its JSON form, or from a database name.

        Parameters
        ----------
        d : dict or str
            ``name``, ``absorption`` (7 values in [0, 1]) and ``scattering`` (0.1 if absent), or
            the name of a database entry (:meth:`from_database`).
        where : str
            Where ``d`` sits in its file (``"room.floor"``), named by errors.

        Returns
        -------
        Material
        """
        if isinstance(d, str):
            try:
                return cls.from_database(check_text(d, where))
            except VrechoError as e:
                raise VrechoError(f"{where}: {e}") from None
        check_keys(d, ("name", "absorption", "scattering"), where)
        name = check_text(check_field(d, "name", where, "custom"), f"{where}.name")
        vals = check_vector(check_field(d, "absorption", where), f"{where}.absorption", len(BANDS_HZ), lo=0.0, hi=1.0)
        return cls(name, tuple(vals.tolist()),
                   check_number(check_field(d, "scattering", where, 0.1), f"{where}.scattering", lo=0.0, hi=1.0))

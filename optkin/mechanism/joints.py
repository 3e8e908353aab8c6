"""Joint types as data: what each letter of a leg string stands for.

A joint is one to three elementary screw motions about axes given at the home
configuration: ``R`` a rotation about a line, ``P`` a translation along a direction
(Lynch & Park, *Modern Robotics* ch. 4). How each type moves (its motion written once with
CasADi operations, and the closed forms legs use) is :mod:`optkin.model.joints`, one class
per entry of :data:`JOINT_TYPES`.

=====  ===========  ==============  ===========================================
type   screws       variables       what it is
=====  ===========  ==============  ===========================================
R      R            1 angle         revolute (planar: about z)
P      P            1 length        prismatic (planar: in x-y)
C      R P          angle, length   cylindrical (a rotation about a line and a
                                    translation along it)
U      R R          2 angles        universal (intersecting orthogonal axes)
S      R R R        3 angles        spherical (concurrent orthogonal axes)
=====  ===========  ==============  ===========================================
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["JointType", "JOINT_TYPES", "expand", "n_vars"]


@dataclass(frozen=True)
class JointType:
    """A joint type: its letter, the kind of each elementary screw, variable suffixes."""

    letter: str
    kinds: str
    suffixes: tuple[str, ...]
    name: str

    @property
    def n(self) -> int:
        return len(self.kinds)


#: Joint letter -> :class:`JointType`.
JOINT_TYPES: dict[str, JointType] = {t.letter: t for t in (
    JointType("R", "R", ("",), "revolute"),
    JointType("P", "P", ("",), "prismatic"),
    JointType("C", "RP", ("theta", "d"), "cylindrical"),
    JointType("U", "RR", ("a", "b"), "universal"),
    JointType("S", "RRR", ("a", "b", "c"), "spherical"),
)}


def expand(letters: str) -> str:
    """The elementary screw kinds of a joint string.

    >>> expand("UPS"), expand("RC")
    ('RRPRRR', 'RRP')
    """
    return "".join(JOINT_TYPES[ch].kinds for ch in letters)


def n_vars(letter: str) -> int:
    """How many variables a joint of this type has."""
    return JOINT_TYPES[letter].n

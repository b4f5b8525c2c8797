"""The identified robot as MJCF: the multibody model wmrid's MuJoCo prototype builds
(:func:`wmrid.sim.multibody_model.build_mjcf`), with the identified platform (m_p, d_x, d_y, I_p) and the wheel joints'
damping (F_v) and friction loss (F_d) in it, and an XML comment with every value's std and the provenance.

What MJCF cannot hold is said in the comment: a ball caster's rolling drag is a force wmrid's prototype applies at
every step (resistance x normal load against the contact's velocity), not an element of the model; the identified
drag D_k (N) of each caster is listed so that a user can apply it the same way.  The platform's height, roll and
pitch inertias are not determined by a wheel log: the prototype's (a flat plate ``cg_height`` above the axle) are
used.
"""

from __future__ import annotations

from wmrid.exports.xml_text import xml_comment
from wmrid.model.robot import Caster, PhysicalParameters
from wmrid.sim.multibody_model import MultibodySettings, build_mjcf


def mjcf_text(
    identified: PhysicalParameters,
    casters: tuple[Caster, ...],
    notes: dict[str, str],
    provenance: str,
    drags: list[dict[str, float]] | None = None,
    extra: list[str] | None = None,
) -> str:
    """The MJCF document (module docstring).  notes: quantity -> "value +/- std unit (source)"; drags: the geometric
    caster model's casters ({"x", "y", "D", "D_std"}), when the result has them; extra: sentences to add."""
    xml = build_mjcf(identified, casters, MultibodySettings())
    lines = [
        "wmrid export: the identified robot as wmrid's multibody prototype builds it (MuJoCo).",
        provenance,
        "Identified (value +/- std; source): " + "; ".join(f"{k} = {v}" for k, v in notes.items()) + ".",
        "Not determined by a wheel log (the prototype's values): the height of the centre of mass, the roll and "
        "pitch inertias.",
    ]
    if drags:
        lines.append(
            "Ball caster drag (not expressible in MJCF; apply a force of D against each caster contact's horizontal "
            "velocity; one D stands for every caster at (+-x, y), whose drag columns are the same): "
            + "; ".join(f"casters at (+-{abs(c['x']):.4g}, {c['y']:.4g}) m: D = {c['D']:.4g} +/- {c['D_std']:.2g} N"
                        for c in drags) + "."
        )  # fmt: skip
    else:
        lines.append("The casters are frictionless: the result has no caster drag of known position.")
    lines += [f"{s[0].upper()}{s[1:]}." for s in extra or []]
    head, _, rest = xml.partition("\n")
    return head + "\n" + xml_comment("\n     ".join(lines)) + "\n" + rest + "\n"

"""How a :class:`~.config.CrowdConfig`'s characters get their bodies: :class:`BodiesMixin`,
the methods of the configuration that set each skeleton's mesh with its LOD levels
(automatic ones fitted by the silhouette check, :mod:`..meshes.lod_check`), add its
further mesh variants and its props (:mod:`..meshes.bodies`), and check each mesh
against its skeleton. ``CrowdConfig`` inherits them; they use its ``skeletons``,
``clips``, ``meshes``, ``variants``, ``props`` and LOD settings.
"""

from __future__ import annotations

from ..base.errors import CrowdError
from ..meshes.bodies import MAX_PROPS

__all__ = ["BodiesMixin"]


class BodiesMixin:
    """The body building of :class:`~.config.CrowdConfig`: meshes and their LOD levels,
    mesh variants and props."""

    def add_mesh(self, mesh, lods=(0.25, 0.06, "card", "card")):
        """Set ``mesh`` as its skeleton's proxy, with LODs built at ``lods`` triangle
        ratios and, last, ``"card"`` for each far level (:func:`~.levels.parts_lod`: a box
        per body part, then with small parts joined; ``()`` for none), or ready
        :class:`~.mesh.ProxyMesh` levels (of the same skeleton), optionally followed by
        ``"card"`` (the far level of ``mesh``). LOD ``k`` is drawn once the agent is
        shorter than ``lod_pixels[k - 1]`` pixels (:mod:`.lod`).

        Every automatic level is checked over the poses of the skeleton's clips added
        so far at the size it is switched in at (:func:`.lod_check.fit_levels`): each
        decimated level is the lightest of a few tries whose silhouette strays from the
        full mesh's by at most ``lod_budget_px`` (1 pixel; ``inf``: no check); a level
        none of whose tries passes is replaced by the level before it, and a note
        saying so is added to :attr:`lod_notes` (the bake and the CLI print them).
        Levels an artist made are kept as made."""
        levels = self._levels(mesh, lods)
        self.meshes[mesh.skeleton] = levels
        return levels

    def add_variant(self, mesh, lods=(0.25, 0.06, "card", "card")):
        """Add ``mesh`` as a further mesh variant of its skeleton (after the body of
        :meth:`add_mesh`, which must be set); ``lods`` as for :meth:`add_mesh`. Returns
        the variant's index."""
        if not self.meshes.get(mesh.skeleton):
            raise CrowdError(f"mesh variant {mesh.name!r}: skeleton {mesh.skeleton!r} has no "
                             "body yet (add_mesh first: it is variant 0)")
        names = [lv[0].name for lv in self.mesh_variants(mesh.skeleton)]
        if mesh.name in names:
            raise CrowdError(f"mesh variant {mesh.name!r}: skeleton {mesh.skeleton!r} has a "
                             f"variant of that name already ({names})")
        self.variants.setdefault(mesh.skeleton, []).append(self._levels(mesh, lods))
        return len(names)

    def mesh_variants(self, skeleton: str) -> list:
        """The LOD level lists of ``skeleton``'s mesh variants, variant 0 first (empty
        when it has no mesh)."""
        first = self.meshes.get(skeleton)
        return [first, *self.variants.get(skeleton, [])] if first else []

    def add_prop(self, prop):
        """Add a :class:`~.bodies.Prop` to its skeleton; returns its index (its bit in
        ``agent_props``)."""
        if prop.skeleton not in self.skeletons:
            raise CrowdError(f"prop {prop.name!r}: unknown skeleton {prop.skeleton!r} "
                             f"(known: {sorted(self.skeletons)})")
        self._check_mesh(prop.mesh, f"prop {prop.name!r}: ")
        have = self.props.setdefault(prop.skeleton, [])
        if prop.name in [p.name for p in have]:
            raise CrowdError(f"prop {prop.name!r}: skeleton {prop.skeleton!r} has a prop of "
                             "that name already")
        if len(have) >= MAX_PROPS:
            raise CrowdError(f"prop {prop.name!r}: skeleton {prop.skeleton!r} has "
                             f"{MAX_PROPS} props already, the most a character has")
        have.append(prop)
        return len(have) - 1

    def _levels(self, mesh, lods) -> list:
        from ..meshes.levels import CARD, parts_lod
        from ..meshes.mesh import ProxyMesh
        self._check_mesh(mesh)
        ready = [m for m in lods if isinstance(m, ProxyMesh)]
        if not ready:
            return self._fitted(mesh, tuple(lods))
        else:
            lods = list(lods)
            rest = lods[len(ready):]
            if not all(isinstance(m, ProxyMesh) for m in lods[:len(ready)]) \
                    or not (rest == [] or (len(rest) == 1 and isinstance(rest[0], str)
                                           and rest[0] == CARD)):
                raise CrowdError(f"mesh {mesh.name!r}: LODs are either triangle ratios or "
                                 f"ready meshes, then optionally {CARD!r} (last), got "
                                 f"{[getattr(m, 'name', m) for m in lods]}")
            for k, level in enumerate(ready, start=1):
                if level.skeleton != mesh.skeleton:
                    raise CrowdError(f"mesh {mesh.name!r}: LOD {k} {level.name!r} is for "
                                     f"skeleton {level.skeleton!r}, not {mesh.skeleton!r}")
                self._check_mesh(level, f"mesh {mesh.name!r}: LOD {k}: ")
            # levels an artist made are kept as made: the silhouette check judges the
            # automatic ones
            return [mesh, *ready] + ([parts_lod(mesh)] if rest else [])

    @property
    def lod_notes(self) -> list:
        """What the silhouette check of :meth:`add_mesh` and :meth:`add_variant` refused
        (one line per level; not saved: loading checks nothing again)."""
        return self.__dict__.setdefault("_lod_notes", [])

    def _fitted(self, mesh, lods) -> list:
        """``mesh``'s automatic levels, each the lightest that passes the silhouette check
        at its switch size (:func:`.lod_check.fit_levels`)."""
        from ..meshes.lod import switch_pixels
        from ..meshes.lod_check import clip_poses, fit_levels
        sk = self.skeletons[mesh.skeleton]
        levels, notes = fit_levels(mesh, lods, sk, clip_poses(sk, self.clips.values()),
                                   switch_pixels(self), float(self.lod_budget_px))
        self.lod_notes.extend(f"mesh {mesh.name!r}: {n}" for n in notes)
        return levels

    def _check_mesh(self, mesh, what=""):
        if mesh.skeleton not in self.skeletons:
            raise CrowdError(f"{what}mesh {mesh.name!r}: unknown skeleton {mesh.skeleton!r} "
                             f"(known: {sorted(self.skeletons)})")
        bones = self.skeletons[mesh.skeleton].bone_count
        if int(mesh.bone_indices.max()) >= bones:
            raise CrowdError(f"{what}mesh {mesh.name!r}: uses bone "
                             f"{int(mesh.bone_indices.max())} but skeleton {mesh.skeleton!r} "
                             f"has {bones} bones")

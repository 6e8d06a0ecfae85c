"""Named, indexed coordinate frames and the rigid transforms between them (pure numerics).

Flight product labels describe frames as ``(name, index)`` — e.g.
``("ROVER_NAV_FRAME", (14, 1262, 6, ...))`` or ``("SITE_FRAME", (14,))`` — and
each coordinate-system group gives one frame relative to a reference frame:
an origin offset and a rotation quaternion with ``p_reference = R(q) p_frame +
offset`` (scalar-first quaternion, the convention of ``RigidTransform``).

:class:`FrameGraph` collects such edges and answers ``T_a_b`` for any two
frames joined by a chain of edges (in either direction).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from .transforms import RigidTransform


@dataclass(frozen=True)
class FrameRef:
    """A frame by name and index (``index`` ``()`` when the label gives none)."""

    name: str
    index: tuple = ()

    def __str__(self) -> str:
        return f"{self.name}{list(self.index) if self.index else ''}"

    def matches(self, other: "FrameRef") -> bool:
        """Same name, and the same index on the leading elements both give.

        A missing index matches any, and ``(30, 1344, 4)`` matches
        ``(30, 1344, 4, 0, 0, 0, 2, 0, 0, 0)`` (PDS4 models name only the
        leading SITE, DRIVE, POSE counters of the rover frame).
        """
        if self.name != other.name:
            return False
        n = min(len(self.index), len(other.index))
        return tuple(self.index[:n]) == tuple(other.index[:n])


class FrameGraph:
    """Rigid transforms between named frames; ``add(T_ref_frame, frame, reference)`` adds one edge."""

    def __init__(self):
        self._edges: list[tuple[FrameRef, FrameRef, RigidTransform]] = []  # (frame, reference, T_reference_frame)

    def add(self, T_reference_frame: RigidTransform, frame: FrameRef, reference: FrameRef) -> None:
        self._edges.append((frame, reference, T_reference_frame))

    def _neighbours(self, node: FrameRef):
        for frame, ref, T_ref_frame in self._edges:
            if frame.matches(node):
                yield ref, T_ref_frame  # node is frame: T_ref_node
            if ref.matches(node):
                yield frame, T_ref_frame.inverse()  # node is ref: T_frame_node

    def transform(self, to: FrameRef, frm: FrameRef) -> Optional[RigidTransform]:
        """``T_to_frm`` (maps points in ``frm`` into ``to``), or ``None`` if no chain of edges joins them."""
        if to.matches(frm):
            return RigidTransform.identity()
        # breadth-first search from ``frm``; each entry carries T_node_frm
        seen = [frm]
        queue = [(frm, RigidTransform.identity())]
        while queue:
            node, T_node_frm = queue.pop(0)
            for nxt, T_nxt_node in self._neighbours(node):
                if any(nxt == s for s in seen):
                    continue
                T_nxt_frm = T_nxt_node @ T_node_frm
                if nxt.matches(to):
                    return T_nxt_frm
                seen.append(nxt)
                queue.append((nxt, T_nxt_frm))
        return None

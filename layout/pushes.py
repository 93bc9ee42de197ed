"""The layout solver's pushes (steps 3 and 4 of :mod:`layout.solver`'s method): the colliding
pairs pushed apart by the smallest horizontal moves, walls pushing objects back into the room,
objects kept on their support, and, when the pushes stall, the nearest free spot. ``Solver``
holds the bodies and their narrow phase; :func:`layout.solver.solve_layout` drives it."""

from __future__ import annotations

import numpy as np

from layout.bodies import Body
from layout.geometry import SupportSurface, clip_half_plane, clip_to_slab_xy, closest_point_in_polygon, horizontal_mtv, placements_inside
from layout.narrowphase import ConvexWorld
from layout.support import SUPPORT_INSET_M, UNSUPPORTED, is_ancestor, subtree, support_inset_m
from scene_builder.config import LayoutConfig
from scene_builder.model import AssetKind, Plane

# Signed distances above -PENETRATION_TOL_M count as touching (resting contacts are exact up to
# floating point).
PENETRATION_TOL_M = 1e-5
# A wall-clearance shortfall smaller than this is not worth a move.
CLEARANCE_TOL_M = 1e-4
# Hysteresis: neighbours are pushed apart to the full clearance, but only once their gap falls
# below this share of it. Without the slack, jammed clusters trade sub-millimetre clearance
# shortfalls around a cycle forever.
CLEARANCE_TRIGGER = 0.5
# An object is slid at most this far from where it was seen to keep its centre of mass the
# stability inset inside its supporting face; beyond, only over the face (keep_on_support).
SUPPORT_SLIDE_MAX_M = 0.05
# A pair pushed apart this many times is from then on separated as a whole (see pair_push).
ESCALATE_AFTER_PUSHES = 4
MAX_JAM_GAP_CLEARANCES = 10
SHUFFLE_AFTER_ITERATIONS = 50
# Nearest-free-spot search (after the pushes stall): radii (m) and directions per ring.
RELOCATE_RADII_M = np.concatenate([np.arange(0.01, 0.5, 0.01), np.arange(0.5, 3.0, 0.05)])
RELOCATE_ANGLES = 32
_FAN = np.stack([np.cos(np.radians(np.arange(0.0, 180.0, 7.5))), np.sin(np.radians(np.arange(0.0, 180.0, 7.5)))], axis=1)
# A soft body sags over an edge until it slides off: its whole footprint is kept on the face
# (shrunk by SUPPORT_INSET_M); when it does not fit, its footprint is scaled about its centre by
# these factors in turn (0: the footprint's centre over the face's).
DEFORMABLE_FIT_SCALES = (1.0, 0.75, 0.5, 0.25, 0.0)


def candidate_pairs(lo_m: np.ndarray, hi_m: np.ndarray, margin_m: float) -> np.ndarray:
    """Broad phase: (P, 2) index pairs i < j whose boxes (N, 3) overlap when grown by ``margin_m``.

    Sort-and-sweep on x (vectorised), then a y/z box test: O(N log N + P) for scattered objects.
    Pairs are sorted lexicographically, so the solver's visiting order is deterministic.
    """
    n = len(lo_m)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    order = np.argsort(lo_m[:, 0], kind="stable")
    xs_lo = lo_m[order, 0]
    end = np.searchsorted(xs_lo, hi_m[order, 0] + margin_m, side="right")
    counts = np.maximum(end - np.arange(1, n + 1), 0)
    total = int(counts.sum())
    if total == 0:
        return np.zeros((0, 2), dtype=np.int64)
    a = np.repeat(np.arange(n), counts)
    starts = np.cumsum(counts) - counts
    b = a + 1 + (np.arange(total) - np.repeat(starts, counts))
    ia, ib = order[a], order[b]
    keep = np.all(lo_m[ia, 1:] <= hi_m[ib, 1:] + margin_m, axis=1) & np.all(lo_m[ib, 1:] <= hi_m[ia, 1:] + margin_m, axis=1)
    pairs = np.sort(np.stack([ia[keep], ib[keep]], axis=1), axis=1)
    return pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))]


class Solver:
    def __init__(self, bodies: list[Body], walls: tuple[Plane, ...], config: LayoutConfig, seed: int = 0) -> None:
        self.bodies = bodies
        self.rng = np.random.default_rng(seed)
        self.walls = walls
        self.clearance = float(config.clearance_m)
        self.max_push = float(config.max_push_m)
        self.world = ConvexWorld([b.pieces for b in bodies])
        # Walls are vertical planes: an object's distance to a wall is the minimum over its
        # (fixed-rotation) vertices of n . v, precomputed once, plus n . position.
        self.wall_n = np.array([w.normal for w in walls], dtype=np.float64).reshape(-1, 3)
        self.wall_off = np.array([w.offset_m for w in walls], dtype=np.float64)
        # A bounded wall holds back only the vertices along its span (where the bodies stand when
        # the solver is made): past its end the room goes on (an opening), and a body wholly
        # there is not held back by it at all.
        self.wall_min_rel = np.full((len(bodies), len(walls)), np.inf)
        for i, b in enumerate(bodies):
            rel = np.concatenate([p.verts_rel_m for p in b.pieces])
            for w, (wall, n) in enumerate(zip(walls, self.wall_n)):
                held = rel[np.isfinite(wall.clearance_m(rel + b.position_m))] if wall.bounded else rel
                if len(held):
                    self.wall_min_rel[i, w] = float(np.min(held @ n))
        for i, b in enumerate(bodies):
            self.world.set_position(i, b.position_m)
        # Pairs found fine, with the body versions they were checked at: re-checked only after
        # one of the two moved.
        self.version = np.zeros(len(bodies), dtype=np.int64)
        self.checked: dict[tuple[int, int], tuple[int, int]] = {}
        self.push_count: dict[tuple[int, int], int] = {}
        self._regions: dict[int, tuple[tuple[int, int], np.ndarray]] = {}
        self.stuck: list[int] = []  # bodies with no room left where seen: left there as background

    # -- state -------------------------------------------------------------------------------
    def boxes(self) -> tuple[np.ndarray, np.ndarray]:
        pos = np.array([b.position_m for b in self.bodies])
        lo = np.array([b.lo_rel_m for b in self.bodies]) + pos
        hi = np.array([b.hi_rel_m for b in self.bodies]) + pos
        return lo, hi

    def move_tree(self, i: int, delta_xy: np.ndarray) -> None:
        for k in subtree(self.bodies, i):
            self.bodies[k].position_m[:2] += delta_xy
            self.world.set_position(k, self.bodies[k].position_m)
            self.version[k] += 1

    def wall_gaps(self, k: int) -> np.ndarray:
        """(W,) signed distance of body k to each wall."""
        return self.wall_min_rel[k] + self.wall_n @ self.bodies[k].position_m + self.wall_off

    def free_travel(self, i: int, direction: np.ndarray) -> float:
        """How far body i (with what rests on it) can slide along ``direction`` (2,) before it
        comes within the clearance of a wall (inf without walls in the way)."""
        if not len(self.wall_n):
            return np.inf
        c = self.wall_n[:, :2] @ direction
        towards = c < -1e-9
        if not np.any(towards):
            return np.inf
        travel = np.inf
        for k in subtree(self.bodies, i):
            gap = self.wall_gaps(k)[towards] - self.clearance
            travel = min(travel, float(np.min(np.maximum(gap, 0.0) / -c[towards])))
        return travel

    def tree_mass(self, i: int) -> float:
        return float(sum(self.bodies[k].mass_kg for k in subtree(self.bodies, i)))

    # -- constraints ---------------------------------------------------------------------------
    def vertical_clash(self, i: int, j: int, z: float) -> float:
        """Penetration depth (m) of body i placed at height z against body j (state restored)."""
        b = self.bodies[i]
        self.world.set_position(j, self.bodies[j].position_m)  # j may have been placed already
        old = b.position_m.copy()
        b.position_m[2] = z
        self.world.set_position(i, b.position_m)
        worst = 0.0
        for a, c in self.piece_pairs(i, j, 0.0):
            d, _ = self.world.distance(self.world.geom_ids[i][a], self.world.geom_ids[j][c], 0.0)
            worst = max(worst, -d)
        b.position_m[:] = old
        self.world.set_position(i, old)
        return worst

    def piece_pairs(self, i: int, j: int, margin: float) -> np.ndarray:
        bi, bj = self.bodies[i], self.bodies[j]
        lo_i, hi_i = bi.piece_lo_rel_m + bi.position_m, bi.piece_hi_rel_m + bi.position_m
        lo_j, hi_j = bj.piece_lo_rel_m + bj.position_m, bj.piece_hi_rel_m + bj.position_m
        ok = np.all(lo_i[:, None, :] <= hi_j[None, :, :] + margin, axis=2) & np.all(lo_j[None, :, :] <= hi_i[:, None, :] + margin, axis=2)
        return np.argwhere(ok)

    def pair_push(self, i: int, j: int, whole: bool = False) -> tuple[np.ndarray, float]:
        """Horizontal direction (2,) and amount (m) to move j relative to i; amount 0 when fine.

        By default the push is the largest of the minimal pushes of the violating piece pairs.
        ``whole``: separate the convex hulls of all violating pieces of each body instead (used
        when minimal pushes cycle, e.g. a table top sliding between another table's legs).
        """
        bi, bj = self.bodies[i], self.bodies[j]
        # Resting on each other, or cut apart by layout.trim (touching with the cut's clearance).
        direct = bi.parent == j or bj.parent == i or bj.name in bi.trimmed_with
        best_dir, best_amount = np.zeros(2), 0.0
        involved: list[tuple[int, int, float]] = []
        for a, b in self.piece_pairs(i, j, self.clearance):
            d, _ = self.world.distance(self.world.geom_ids[i][a], self.world.geom_ids[j][b], self.clearance + 1e-3)
            z_lo = max(bi.piece_lo_rel_m[a, 2] + bi.position_m[2], bj.piece_lo_rel_m[b, 2] + bj.position_m[2])
            z_hi = min(bi.piece_hi_rel_m[a, 2] + bi.position_m[2], bj.piece_hi_rel_m[b, 2] + bj.position_m[2])
            thick = z_hi - z_lo
            if direct:
                # Resting on each other: touching is the point; only real overlap is fixed.
                violated = d < -PENETRATION_TOL_M
            else:
                # Only a real overlap moves anything; a pair pushed apart is separated to the
                # clearance. Neighbours seen touching stay touching: pushing them to the
                # clearance set a cluster shuffling (a cabinet and a night stand of
                # sunrgbd_imvotenet_000003 traded millimetre pushes 200 times, and the night
                # stand then went to a free spot 33 cm from where it was seen).
                violated = d < -PENETRATION_TOL_M
            if not violated or thick <= 0.0:
                continue
            involved.append((int(a), int(b), d))
            if whole:
                continue
            pa, pb = bi.pieces[a], bj.pieces[b]
            xa = clip_to_slab_xy(pa.verts_rel_m + bi.position_m, pa.edges, z_lo, z_hi)
            xb = clip_to_slab_xy(pb.verts_rel_m + bj.position_m, pb.edges, z_lo, z_hi)
            if len(xa) == 0 or len(xb) == 0:
                continue
            u, overlap = horizontal_mtv(xa, xb, np.concatenate([pa.axes_xy, pb.axes_xy]))
            amount = overlap + self.clearance
            if amount <= 1e-9:
                # Projections already apart, yet the pieces are closer than the clearance
                # (slanted faces): open the gap by the shortfall.
                amount = self.clearance - d
            if amount > best_amount:
                best_dir, best_amount = u, amount
        if whole and involved:
            return self._hull_push(i, j, involved)
        return best_dir, best_amount

    def _hull_push(self, i: int, j: int, involved: list[tuple[int, int, float]]) -> tuple[np.ndarray, float]:
        bi, bj = self.bodies[i], self.bodies[j]
        ai = sorted({a for a, _, _ in involved})
        aj = sorted({b for _, b, _ in involved})
        z_lo = max(min(bi.piece_lo_rel_m[a, 2] for a in ai) + bi.position_m[2], min(bj.piece_lo_rel_m[b, 2] for b in aj) + bj.position_m[2])
        z_hi = min(max(bi.piece_hi_rel_m[a, 2] for a in ai) + bi.position_m[2], max(bj.piece_hi_rel_m[b, 2] for b in aj) + bj.position_m[2])
        xa = np.concatenate([clip_to_slab_xy(bi.pieces[a].verts_rel_m + bi.position_m, bi.pieces[a].edges, z_lo, z_hi) for a in ai])
        xb = np.concatenate([clip_to_slab_xy(bj.pieces[b].verts_rel_m + bj.position_m, bj.pieces[b].edges, z_lo, z_hi) for b in aj])
        if len(xa) == 0 or len(xb) == 0:
            return np.zeros(2), 0.0
        # Any axis gives a valid (separating) push; the pieces' own axes plus a 7.5-degree fan
        # approximate the hulls' edge normals without building the hulls.
        axes = np.concatenate([bi.pieces[a].axes_xy for a in ai] + [bj.pieces[b].axes_xy for b in aj] + [_FAN])
        u, overlap = horizontal_mtv(xa, xb, axes)
        worst = min(d for _, _, d in involved)
        return u, max(overlap + self.clearance, self.clearance - worst)

    def movers(self, i: int, j: int) -> tuple[int, int]:
        """The bodies that move when i and j collide: for each, its highest support ancestor
        below their lowest common one (-1: none moves on that side, i.e. it supports the other).

        Two boxes on one table slide on the table; a box on table A touching table B moves all
        of A (what rests on a body travels with it, and a push that the support-containment step
        would undo is never tried)."""
        path_i, path_j = [i], [j]
        while self.bodies[path_i[-1]].parent >= 0:
            path_i.append(self.bodies[path_i[-1]].parent)
        while self.bodies[path_j[-1]].parent >= 0:
            path_j.append(self.bodies[path_j[-1]].parent)
        common = set(path_i) & set(path_j)

        def branch(path: list[int]) -> int:
            out = -1
            for k in path:
                if k in common or (self.bodies[k].fixed and out >= 0):
                    break  # a fixed supporter (left where seen) carries nothing away
                out = k
            return out

        return branch(path_i), branch(path_j)

    def resolve_pair(self, i: int, j: int) -> bool:
        bodies = self.bodies
        if self.checked.get((i, j)) == (self.version[i], self.version[j]):
            return False
        mover_i, mover_j = self.movers(i, j)
        share_i = 0.0 if mover_i < 0 or bodies[mover_i].fixed else 1.0
        share_j = 0.0 if mover_j < 0 or bodies[mover_j].fixed else 1.0
        if share_i == 0.0 and share_j == 0.0:
            return False
        pushes = self.push_count.get((i, j), 0)
        if share_i > 0.0 and share_j > 0.0:
            if pushes < ESCALATE_AFTER_PUSHES:
                # Split by mass: the lighter stack moves more.
                mi, mj = self.tree_mass(mover_i), self.tree_mass(mover_j)
                share_i, share_j = mj / (mi + mj), mi / (mi + mj)
            else:
                # A light object trapped between heavy ones would otherwise shuttle between
                # them: in a jam both sides give way equally, so the cluster spreads out.
                share_i = share_j = 0.5
        # Minimal pushes first; a pair pushed again and again is separated as a whole.
        u, amount = self.pair_push(i, j, whole=pushes >= ESCALATE_AFTER_PUSHES)
        if amount <= 0.0:
            self.checked[(i, j)] = (self.version[i], self.version[j])
            return False
        if amount > self.max_push:
            # Clearing this overlap sideways would move what was seen too far (a table under a
            # blanket seen on it): the lighter movable side cannot stand where it was seen.
            sides = [m for m, sh in ((mover_i, share_i), (mover_j, share_j)) if sh > 0.0]
            k = min(sides, key=lambda m: (self.tree_mass(m), self.bodies[m].name))
            other = bodies[j if k == mover_i else i].name
            self.leave_where_seen(k, f"would have to move {amount * 100:.0f} cm sideways to clear {other}")
            return True
        self.push_count[(i, j)] = pushes + 1
        if pushes >= ESCALATE_AFTER_PUSHES:
            # Over-relax inside jams: each repeated push leaves a little more room (up to
            # MAX_JAM_GAP_CLEARANCES clearances), so a dense cluster spreads out in a few sweeps
            # instead of trading sub-millimetre overlaps around a ring.
            amount += self.clearance * min(pushes - ESCALATE_AFTER_PUSHES + 1, MAX_JAM_GAP_CLEARANCES)
        # A body that a wall stops hands the rest of the move to the other one.
        move_j = amount * share_j
        move_i = amount - move_j
        if share_i > 0 and share_j > 0:
            move_j = min(move_j, self.free_travel(mover_j, u))
            move_i = amount - move_j
            if move_i > self.free_travel(mover_i, -u):
                move_i = self.free_travel(mover_i, -u)
                move_j = amount - move_i
        # Pushes add up: one that would take a body more than max_push from where it was seen
        # (a cluster spreading out over many sweeps) means it cannot stand there either.
        for m, step in ((mover_j, u * move_j), (mover_i, -u * move_i)):
            if np.any(step):
                b = self.bodies[m]
                total = float(np.linalg.norm(b.position_m[:2] + step - b.initial_position_m[:2]))
                if total > self.max_push:
                    other = bodies[i if m == mover_j else j].name
                    self.leave_where_seen(m, f"would have to move {total * 100:.0f} cm sideways in all to clear {other} and its neighbours")
                    return True
        if move_j > 0:
            self.move_tree(mover_j, u * move_j)
        if move_i > 0:
            self.move_tree(mover_i, -u * move_i)
        return True

    def push_out_of_walls(self) -> bool:
        if not len(self.wall_n):
            return False
        pos = np.array([b.position_m for b in self.bodies])
        gaps = self.wall_min_rel + pos @ self.wall_n.T + self.wall_off  # (N, W)
        moved = False
        for i, w in np.argwhere(self.clearance - gaps > CLEARANCE_TOL_M):
            if self.bodies[int(i)].fixed:
                continue  # fixed furniture and objects left where seen never move
            n_xy = self.wall_n[w, :2]
            norm = float(np.linalg.norm(n_xy))
            short = self.clearance - float(self.wall_gaps(int(i))[w])  # earlier moves count
            if norm > 1e-9 and short > CLEARANCE_TOL_M:
                self.move_tree(int(i), n_xy / norm * (short / norm))
                moved = True
        return moved

    def support_face(self, i: int) -> SupportSurface:
        """The face body i rests on: the step of a merged top under it where it rests on one
        (``Body.step_face``), else its supporting face."""
        b = self.bodies[i]
        return b.step_face or self.bodies[b.parent].surfaces[b.support_surface]

    def support_region(self, i: int) -> np.ndarray:
        """(K, 2) convex polygon, relative to the supporting body's position, of the positions
        (x, y) at which body i rests stably on its supporting face: a rigid body's centre of mass
        inside the face by its stability inset, a soft body's footprint on the face. Cached: it
        depends only on the two bodies' shapes."""
        b = self.bodies[i]
        key = (b.parent, b.support_surface, id(b.step_face))
        cached = self._regions.get(i)
        if cached is not None and cached[0] == key:
            return cached[1]
        face = self.support_face(i).polygon_rel_m
        region = np.zeros((0, 2))
        if b.asset.kind is AssetKind.DEFORMABLE:
            centre = b.footprint_rel_m.mean(axis=0)
            for scale in DEFORMABLE_FIT_SCALES:
                region = placements_inside(face, centre + (b.footprint_rel_m - centre) * scale, SUPPORT_INSET_M)
                if len(region):
                    break
        else:
            region = placements_inside(face, b.com_rel_m[None, :2], support_inset_m(b))
        if not len(region):
            # Nothing fits (a face smaller than the inset): centre of mass over the face's centre.
            region = (face.mean(axis=0) - b.com_rel_m[:2])[None]
        self._regions[i] = (key, region)
        return region

    def inside_walls(self, i: int, region: np.ndarray) -> np.ndarray:
        """The positions (x, y) of ``region`` (K, 2) at which body i (and what rests on it, whose
        relative offsets stay) keeps the clearance from every wall."""
        if not len(self.wall_n):
            return region
        b = self.bodies[i]
        for k in subtree(self.bodies, i):
            off = self.bodies[k].position_m - b.position_m
            for w in range(len(self.wall_n)):
                if not np.isfinite(self.wall_min_rel[k, w]):
                    continue  # (past the wall's end)
                n = self.wall_n[w]
                # gap = wall_min_rel + n . (pos + off) + wall_off >= clearance
                rhs = self.clearance - self.wall_min_rel[k, w] - self.wall_off[w] - float(n @ off) - n[2] * b.position_m[2]
                region = clip_half_plane(region, n[:2], rhs)
                if len(region) == 0:
                    return region
        return region

    def keep_on_support(self) -> bool:
        moved = False
        for i, b in enumerate(self.bodies):
            if b.parent < 0 or b.fixed or b.support_surface < 0:
                continue
            s = self.bodies[b.parent]
            region = self.inside_walls(i, self.support_region(i) + s.position_m[:2])
            if len(region) == 0:
                # Stable spots all lie in a wall: the wall wins, the settle simulation judges
                # whether the object still stands (relaxed to its centre of mass over the face).
                face = self.support_face(i).polygon_rel_m + s.position_m[:2] - b.com_rel_m[:2]
                region = self.inside_walls(i, face)
                if len(region) == 0:
                    continue
            here = b.position_m[:2]
            target = region[0] if len(region) < 3 else closest_point_in_polygon(here, region, 0.0)
            # How far it may end from where it was seen: SUPPORT_SLIDE_MAX_M, or as far as the
            # pushes have already taken it (a bowl pushed 16 cm off its shelf board's edge by its
            # neighbours is brought back onto the board, nearer where it was seen: promptda_arkit).
            slide = max(SUPPORT_SLIDE_MAX_M, float(np.linalg.norm(here - b.initial_position_m[:2])))
            if float(np.linalg.norm(target - b.initial_position_m[:2])) > slide and b.asset.kind is not AssetKind.DEFORMABLE:
                # Seen nearer the face's edge than the stability inset (or over a face modelled
                # smaller than the real top): the centre of mass only has to be over the face;
                # farther than that from where it was seen it stays, and the settle simulation
                # judges whether it stands.
                face = self.support_face(i).polygon_rel_m + s.position_m[:2]
                relaxed = self.inside_walls(i, placements_inside(face - s.position_m[:2], b.com_rel_m[None, :2], SUPPORT_INSET_M) + s.position_m[:2])
                if not len(relaxed):
                    continue
                target = relaxed[0] if len(relaxed) < 3 else closest_point_in_polygon(here, relaxed, 0.0)
                if float(np.linalg.norm(target - b.initial_position_m[:2])) > slide:
                    continue
            delta = target - here
            if float(np.linalg.norm(delta)) > 1e-6:
                self.move_tree(i, delta)
                moved = True
        return moved

    def run(self, max_iterations: int) -> tuple[int, bool]:
        for it in range(max_iterations):
            moved = False
            lo, hi = self.boxes()
            pairs = candidate_pairs(lo, hi, self.clearance)
            if it >= SHUFFLE_AFTER_ITERATIONS:
                # Late sweeps visit the pairs in a seeded random order: a jam whose pushes cancel
                # in a fixed order is broken up (deterministic for a given seed).
                pairs = pairs[self.rng.permutation(len(pairs))]
            for i, j in pairs:
                moved |= self.resolve_pair(int(i), int(j))
            moved |= self.push_out_of_walls()
            moved |= self.keep_on_support()
            if not moved:
                return it + 1, True
        return max_iterations, False

    # -- last resort: the nearest free spot ---------------------------------------------------
    def penetrating_pairs(self) -> list[tuple[int, int]]:
        """Pairs of bodies whose pieces overlap by more than PENETRATION_TOL_M."""
        out = []
        lo, hi = self.boxes()
        for i, j in candidate_pairs(lo, hi, 0.0):
            i, j = int(i), int(j)
            for a, b in self.piece_pairs(i, j, 0.0):
                d, _ = self.world.distance(self.world.geom_ids[i][a], self.world.geom_ids[j][b], 0.0)
                if d < -PENETRATION_TOL_M:
                    out.append((i, j))
                    break
        return out

    def tree_is_free(self, tree: list[int]) -> bool:
        """Whether the bodies of ``tree`` (a body and what rests on it) keep half the clearance
        from every other body (touching their supports) and the full clearance from the walls."""
        inside = set(tree)
        lo, hi = self.boxes()
        margin = CLEARANCE_TRIGGER * self.clearance
        for k in tree:
            if len(self.wall_n) and float(np.min(self.wall_gaps(k))) < self.clearance - CLEARANCE_TOL_M:
                return False
            near = np.nonzero(np.all(lo <= hi[k] + margin, axis=1) & np.all(lo[k] <= hi + margin, axis=1))[0]
            for j in near:
                j = int(j)
                if j in inside:
                    continue
                need = -PENETRATION_TOL_M if is_ancestor(self.bodies, j, k) else margin
                for a, b in self.piece_pairs(k, j, margin):
                    d, _ = self.world.distance(self.world.geom_ids[k][a], self.world.geom_ids[j][b], margin + 1e-3)
                    if d < need:
                        return False
        return True

    def relocate(self, i: int) -> bool:
        """Move body i (with what rests on it) to the nearest free spot on its support: rings of
        RELOCATE_ANGLES candidate moves at growing radii, the first free one wins (the smallest
        move that the greedy pushes could not find). Returns whether a spot was found."""
        b = self.bodies[i]
        tree = subtree(self.bodies, i)
        region = None
        if b.parent >= 0 and b.support_surface >= 0:
            region = self.support_region(i) + self.bodies[b.parent].position_m[:2]
        start = b.position_m[:2].copy()
        angles = np.radians(np.arange(RELOCATE_ANGLES) * 360.0 / RELOCATE_ANGLES)
        ring = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        for r in RELOCATE_RADII_M:
            for u in ring:
                target = start + r * u
                if region is not None and len(region) >= 3 and not np.allclose(closest_point_in_polygon(target, region, 0.0), target):
                    continue
                self.move_tree(i, target - b.position_m[:2])
                if self.tree_is_free(tree):
                    return True
        self.move_tree(i, start - b.position_m[:2])
        return False

    def relocate_remaining(self) -> bool:
        """For every pair still interpenetrating, move the lighter movable side to its nearest
        free spot. Returns whether anything moved."""
        moved = False
        for i, j in self.penetrating_pairs():
            if not self.penetrating_pair(i, j):
                continue  # an earlier relocation fixed it
            mi, mj = self.movers(i, j)
            sides = [m for m in (mi, mj) if m >= 0 and not self.bodies[m].fixed]
            ordered = sorted(sides, key=lambda k: (self.tree_mass(k), self.bodies[k].name))
            if any(self.relocate(m) for m in ordered):
                moved = True
                continue
            # No room left on the support (two cabinets on one cabinet's top): the lighter side
            # that rests on an object cannot stand where it was seen; it stays there as static
            # background (never dropped to the floor metres from its pixels).
            on_object = [m for m in ordered if self.bodies[m].parent >= 0]
            if on_object:
                self.leave_where_seen(on_object[0], "no room on its support clear of its neighbours")
                moved = True
            elif ordered:
                # Jammed against static geometry (an object left where seen) with no free spot
                # near: it cannot stand clear where it was seen either.
                other = self.bodies[j if ordered[0] == i else i].name
                self.leave_where_seen(ordered[0], f"no room clear of {other} near where it was seen")
                moved = True
        for k in self.wall_violators():
            if not len(self.wall_violators([k])):
                continue
            # Its support's stable region reaches through the wall: move the body, else what it
            # rests on, else bring it down to the floor.
            chain = [k]
            while self.bodies[chain[-1]].parent >= 0:
                chain.append(self.bodies[chain[-1]].parent)
            if any(self.relocate(m) for m in chain if not self.bodies[m].fixed):
                moved = True
            elif self.bodies[k].parent >= 0 and not self.bodies[k].fixed:
                self.leave_where_seen(k, "its support's stable spots all reach into a wall")
                moved = True
        return moved

    def wall_violators(self, which: list[int] | None = None) -> list[int]:
        """Bodies (of ``which``, default all) that reach through a wall by more than
        PENETRATION_TOL_M."""
        if not len(self.wall_n):
            return []
        which = list(range(len(self.bodies))) if which is None else which
        return [k for k in which if float(np.min(self.wall_gaps(k))) < -PENETRATION_TOL_M]

    def leave_where_seen(self, i: int, reason: str) -> None:
        """Put body i (with what rests on it) back where it was seen and fix it there: it becomes
        static background after the solve (``stuck``); the others make room around it."""
        b = self.bodies[i]
        if b.parent >= 0:
            self.bodies[b.parent].children.remove(i)
        b.parent, b.support_surface, b.fixed, b.unsupported_reason = UNSUPPORTED, -1, True, reason
        self._regions.pop(i, None)
        delta = b.initial_position_m - b.position_m
        for k in subtree(self.bodies, i):
            self.bodies[k].position_m += delta
            self.world.set_position(k, self.bodies[k].position_m)
            self.version[k] += 1
        self.stuck.append(i)

    def penetrating_pair(self, i: int, j: int) -> bool:
        for a, b in self.piece_pairs(i, j, 0.0):
            d, _ = self.world.distance(self.world.geom_ids[i][a], self.world.geom_ids[j][b], 0.0)
            if d < -PENETRATION_TOL_M:
                return True
        return False

    # -- measurement ---------------------------------------------------------------------------
    def max_penetration(self) -> float:
        """Deepest overlap (m) between pieces of distinct objects, and of objects with the floor
        and the walls, measured exactly (GJK/EPA). Objects left where seen as static background
        (``UNSUPPORTED``) join the room's static geometry: their overlaps with each other, the
        floor and the walls are not overlaps between bodies."""
        worst = 0.0
        lo, hi = self.boxes()
        static = [b.parent == UNSUPPORTED for b in self.bodies]
        for i, j in candidate_pairs(lo, hi, 0.0):
            if static[i] and static[j]:
                continue
            for a, b in self.piece_pairs(int(i), int(j), 0.0):
                d, _ = self.world.distance(self.world.geom_ids[i][a], self.world.geom_ids[j][b], 0.0)
                worst = max(worst, -d)
        for b in self.bodies:
            if b.parent == UNSUPPORTED:
                continue
            worst = max(worst, -b.bottom_m)
            if self.walls:
                v = b.world_vertices()
                worst = max(worst, max(-float(np.min(w.clearance_m(v))) for w in self.walls))
        return worst

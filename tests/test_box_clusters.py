"""The pieces that make a detector box's object whole (perception.box_clusters) and the wall
test that keeps a headboard from being a wall (perception.room._wall_behind), on small
hand-made arrays."""

from __future__ import annotations

import numpy as np

from perception.box_clusters import cuboid_faces, fill_box


def test_cuboid_faces_join_the_faces_inside_the_box_that_touch_the_object_face_by_face():
    # Clusters in an 8 x 8 box: 1 the front (the object's own), 2 the top touching it, 3 the
    # headboard touching only the top, 4 a thing inside the box touching nothing of the object,
    # 5 reaching far out of the box (the wall behind).
    clusters = np.zeros((20, 20), dtype=np.int64)
    clusters[14:18, 4:12] = 1
    clusters[11:14, 4:12] = 2
    clusters[8:11, 5:11] = 3
    clusters[15:18, 14:16] = 4  # inside the box, 3 px from the front: not joined
    clusters[0:10, 0:20] = np.where(clusters[0:10, 0:20] == 0, 5, clusters[0:10, 0:20])
    rs, cs = slice(8, 18), slice(3, 17)
    cl = clusters[rs, cs]
    own = cl == 1
    faces = cuboid_faces(own, cl, clusters, 1)
    got = set(np.unique(cl[faces]).tolist())
    assert got == {2, 3}  # the top, and the headboard through it; not the separate thing, not the wall
    assert not (faces & own).any()


def test_fill_box_grows_a_screen_to_its_case_and_leaves_a_full_cut_and_other_things_alone():
    h, w = 40, 60
    box = np.array([10.0, 5.0, 50.0, 35.0])
    screen = np.zeros((h, w), dtype=bool)
    screen[12:28, 18:42] = True  # 16 x 24 of the 30 x 40 box: 32 %
    bottle = np.zeros((h, w), dtype=bool)
    bottle[20:35, 10:15] = True  # another instance standing in front of the case
    out = fill_box(box, screen, np.zeros((h, w), dtype=bool), [bottle])
    assert out[5:35, 10:50].sum() == 30 * 40 - bottle[5:35, 10:50].sum()
    assert not (out & bottle).any() and not out[:5].any() and not out[:, 50:].any()
    full = np.zeros((h, w), dtype=bool)
    full[6:34, 11:49] = True  # 89 % of the box: a cut that already holds the thing is kept
    assert np.array_equal(fill_box(box, full, np.zeros((h, w), dtype=bool), []), full)


def test_a_plane_with_a_larger_parallel_wall_behind_it_is_no_wall():
    from perception.room import CameraPlane, _wall_behind

    def plane(offset, n_inliers, normal=(0.0, 0.0, -1.0), kind="wall"):
        inl = np.zeros((100, 100), dtype=bool)
        inl.flat[:n_inliers] = True
        return CameraPlane(np.asarray(normal), offset, kind, inl)

    back = plane(4.3, 5000)  # the back wall, seen over most of the photo
    headboard = plane(3.7, 1500)  # a bed's headboard 0.6 m in front of it, parallel
    side = plane(2.0, 800, normal=(1.0, 0.0, 0.0))  # a side wall: not parallel
    skirting = plane(4.1, 300)  # parallel but within WALL_MERGE_M: the same wall's skirting
    planes = [back, headboard, side, skirting]
    assert _wall_behind(headboard, planes)
    assert not _wall_behind(back, planes) and not _wall_behind(side, planes) and not _wall_behind(skirting, planes)
    # A nearer wall that shows more of itself than the far one stays (the far one is seen past its end).
    assert not _wall_behind(plane(3.7, 6000), planes)

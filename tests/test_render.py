"""Renderer behaviour: geometry (symmetry, side cameras, bumps), lighting, cones, determinism, caching."""

from __future__ import annotations

import math

import numpy as np
import pytest

from protocol.facts import FRAME_HEIGHT, FRAME_WIDTH
from tools.sim.render.renderer import Renderer
from tools.sim.render.world import Pose, World, clear_caches, get_world, sun_for
from tools.sim.track.cones import place_cones
from tools.sim.track.files import load_track, parse_track
from tools.sim.track.road import Track

CLASSIC = "classic"  # the geometry below is the first headless camera's (horizon row 70, no bonnet)

STRAIGHT = 160.0  # metres of straight road in the test stadium


def stadium(trees: int = 0, **extra) -> Track:
    """A small stadium-shaped loop: two long straights (along x, driven east at the bottom) and two U-turns."""
    r, n = 40.0, 12
    pts = [[x, -r] for x in np.linspace(0, STRAIGHT, 9)[:-1]]
    pts += [[STRAIGHT + r * math.sin(a), -r * math.cos(a)] for a in np.linspace(0, math.pi, n + 1)[:-1]]
    pts += [[x, r] for x in np.linspace(STRAIGHT, 0, 9)[:-1]]
    pts += [[-r * math.sin(a), r * math.cos(a)] for a in np.linspace(0, math.pi, n + 1)[:-1]]
    data = {"name": "stadium", "version": 1, "centerline": pts, "road_width": 8.0, "shoulder_width": 1.0,
            "scenery": {"trees": {"count": trees, "seed": 2, "min_offset": 6.0, "max_offset": 18.0}},
            "sun": {"azimuth_deg": 120.0, "elevation_deg": 35.0}, **extra}
    return parse_track(data, "stadium")


@pytest.fixture(scope="module")
def bare() -> Renderer:
    return Renderer(World(stadium()), rig=CLASSIC)


@pytest.fixture(scope="module")
def wooded() -> Track:
    return stadium(trees=60)


def on_straight(offset: float = 0.0, x: float = 20.0) -> Pose:
    return Pose(x, -40.0 + offset, 0.0)  # heading east along the bottom straight


def ground(img: np.ndarray, near_rows: int = 60) -> np.ndarray:
    """The nearest ``near_rows`` rows of ground (well below the horizon)."""
    return img[FRAME_HEIGHT - near_rows:].astype(np.int32)


def road_centre(img: np.ndarray) -> float:
    """Mean column of the asphalt 10-20 m ahead (rows where the whole road width is in view)."""
    return float(np.nonzero(asphalt_mask(img[84:100]))[1].mean())


def asphalt_mask(img: np.ndarray) -> np.ndarray:
    """Grey road pixels: dark-ish and unsaturated (grass is green, lines white, shoulders brown)."""
    rgb = img.astype(np.int32)
    spread = rgb.max(-1) - rgb.min(-1)
    return (spread < 14) & (rgb.mean(-1) < 150)


def test_frame_format_and_camera_names(bare: Renderer):
    img = bare.render(on_straight())
    assert img.shape == (FRAME_HEIGHT, FRAME_WIDTH, 3) and img.dtype == np.uint8 and img.flags.c_contiguous
    with pytest.raises(ValueError, match="unknown camera 'roof'"):
        bare.render(on_straight(), camera="roof")
    assert set(bare.render_all(on_straight())) == {"left", "center", "right"}


def test_straight_road_is_left_right_symmetric(bare: Renderer):
    img = bare.render(on_straight())
    g = ground(img)
    road = asphalt_mask(g)
    assert road[:, FRAME_WIDTH // 2].all()  # the centre column sees road all the way down
    mirrored = road[:, ::-1]
    agree = (road == mirrored).mean()
    assert agree > 0.97, f"road mask only {agree:.3f} symmetric"
    # colour per column, averaged over rows, also mirrors (grain averages out)
    prof = g.mean(0)
    assert np.abs(prof - prof[::-1]).mean() < 6.0


def test_side_cameras_see_the_road_shifted(bare: Renderer):
    centres = {cam: road_centre(bare.render(on_straight(), cam)) for cam in ("left", "center", "right")}
    # the left camera sits left of the car, so the road appears further right, and vice versa
    assert centres["left"] > centres["center"] + 5
    assert centres["right"] < centres["center"] - 5
    assert abs((centres["left"] - centres["center"]) - (centres["center"] - centres["right"])) < 2


def test_car_left_of_centre_sees_road_to_the_right(bare: Renderer):
    assert road_centre(bare.render(on_straight(offset=1.5))) > road_centre(bare.render(on_straight())) + 5


def test_pitch_up_lowers_the_horizon_and_roll_tilts_it(bare: Renderer):
    def horizon(img: np.ndarray) -> np.ndarray:
        """Per column: first row from the top whose pixel is green-ish ground (not sky)."""
        rgb = img.astype(np.int32)
        groundish = rgb[..., 1] > rgb[..., 2] + 5
        return np.argmax(groundish, axis=0)

    flat = np.median(horizon(bare.render(on_straight())))
    up = np.median(horizon(bare.render(on_straight(), pitch_deg=2.0)))
    assert up > flat + 2  # nose up: the world drops in the image
    h = horizon(bare.render(on_straight(), roll_deg=3.0))
    assert np.median(h[:40]) > np.median(h[-40:]) + 3  # right side down: horizon higher on the right


def test_light_intensity_is_monotone_and_leaves_ambient(wooded: Track):
    r = Renderer(get_world(wooded), rig=CLASSIC)
    pose = on_straight()
    means = [r.render(pose, light_intensity=v).mean() for v in (0.1, 0.5, 1.0, 1.5, 2.0)]
    assert all(b > a + 1.0 for a, b in zip(means, means[1:], strict=False)), means
    assert np.array_equal(r.render(pose, light_intensity=1.0), r.render(pose))
    with pytest.raises(ValueError):
        r.render(pose, light_intensity=-1.0)


def test_light_direction_moves_shadows(wooded: Track):
    pose = on_straight(x=60.0)
    a = Renderer(get_world(wooded, 0.0), rig=CLASSIC).render(pose)
    b = Renderer(get_world(wooded, 20.0), rig=CLASSIC).render(pose)
    rows = slice(FRAME_HEIGHT // 2 + 10, FRAME_HEIGHT)
    diff = np.abs(a[rows].astype(int) - b[rows].astype(int)).max(-1)
    assert (diff > 25).mean() > 0.02  # shadows moved somewhere on the ground
    sun0, sun1 = sun_for(wooded, 0.0), sun_for(wooded, 20.0)
    assert sun1.elevation_deg == pytest.approx(sun0.elevation_deg + 20.0)
    assert sun_for(wooded, 80.0).azimuth_deg == pytest.approx((sun0.azimuth_deg + 180.0) % 360.0)


def test_cones_are_drawn_on_their_half_of_the_road():
    track = stadium()
    cones = np.array([[60.0, -40.0 + 2.0]])  # 2 m left of the centre line, on the bottom straight
    with_cone = Renderer(get_world(track, cones=cones), rig=CLASSIC).render(on_straight(x=50.0))
    without = Renderer(get_world(track), rig=CLASSIC).render(on_straight(x=50.0))
    changed = np.abs(with_cone.astype(int) - without.astype(int)).max(-1) > 30
    ys, xs = np.nonzero(changed)
    assert len(xs) > 40  # a 0.9 m cone 10 m ahead covers a visible patch
    assert xs.mean() < FRAME_WIDTH / 2 - 10  # left of the image centre
    orange = with_cone[ys, xs].astype(int)
    assert ((orange[:, 0] > 150) & (orange[:, 2] < 100)).any()


def test_place_cones_block_the_rendered_road():
    track = stadium()
    cones = place_cones(track, 4, seed=5)
    r = Renderer(get_world(track, cones=cones), rig=CLASSIC)
    p = track.project(*cones[0])
    x, y, h = track.point_at(p.s - 9.0)
    img = r.render(Pose(x, y, h))
    rgb = img.astype(int)
    orange = (rgb[..., 0] > 170) & (rgb[..., 1] < 140) & (rgb[..., 2] < 90)
    assert orange.sum() > 20
    side = np.nonzero(orange)[1].mean() - FRAME_WIDTH / 2
    assert np.sign(side) == -np.sign(p.cte)  # a cone on the left half shows left of centre


def test_rendering_is_deterministic(wooded: Track):
    pose = on_straight(offset=0.7, x=45.0)
    first = Renderer(get_world(wooded), rig=CLASSIC).render(pose, "left", light_intensity=0.7, pitch_deg=0.4,
                                                            roll_deg=-0.3)
    clear_caches()
    again = Renderer(World(wooded), rig=CLASSIC).render(pose, "left", light_intensity=0.7, pitch_deg=0.4,
                                                        roll_deg=-0.3)
    assert np.array_equal(first, again)


def test_worlds_are_cached_by_track_light_and_cones(wooded: Track):
    a = get_world(wooded, 5.0)
    assert get_world(wooded, 5.0) is a
    assert get_world(wooded, 6.0) is not a
    assert get_world(wooded, 5.0, cones=np.array([[10.0, -40.0]])) is not a


def test_bridge_looks_different_from_asphalt():
    track = stadium(surfaces=[{"from_s": 60.0, "to_s": 110.0, "kind": "bridge"}])
    r = Renderer(get_world(track), rig=CLASSIC)

    def road_colour(s: float) -> np.ndarray:
        x, y, h = track.point_at(s)
        img = r.render(Pose(x, y, h))
        return img[FRAME_HEIGHT - 25:, FRAME_WIDTH // 2 - 30: FRAME_WIDTH // 2 + 30].reshape(-1, 3).mean(0)

    deck, asphalt = road_colour(85.0), road_colour(30.0)
    assert deck[0] - deck[2] > 30  # warm brown planks
    assert abs(asphalt[0] - asphalt[2]) < 15  # neutral grey asphalt


def test_the_unity_rig_is_the_default_and_the_classic_one_is_kept():
    from tools.sim.render.camera import DEFAULT_RIG, LEGACY_RIG

    assert (DEFAULT_RIG, LEGACY_RIG) == ("unity", "classic")
    track = load_track("lake")
    x, y, h = track.point_at(100.0)
    world = get_world(track)
    assert np.array_equal(Renderer(world).render(Pose(x, y, h)), Renderer(world, rig="unity").render(Pose(x, y, h)))


def test_the_unity_rig_sees_the_horizon_and_the_bonnet_where_the_real_camera_does():
    from tools.sim.render.camera import camera_models

    unity, classic = camera_models("unity"), camera_models("classic")
    assert unity["center"].horizon_row in (64, 65) and classic["center"].horizon_row == 70
    track = load_track("lake")
    x, y, h = track.point_at(100.0)
    frames = Renderer(get_world(track), rig="unity").render_all(Pose(x, y, h))
    grey = {k: f.mean(axis=2) for k, f in frames.items()}
    bonnet = np.array([172, 178, 164])
    assert np.abs(frames["center"][150, 160].astype(int) - bonnet).max() < 20  # the bonnet, mid-frame
    assert np.abs(frames["center"][130, 160].astype(int) - bonnet).max() > 20  # the road above it
    assert abs(grey["left"][155, 290] - 170) < 20 and abs(grey["left"][155, 30] - 170) > 20  # moved right
    assert abs(grey["right"][155, 30] - 170) < 20 and abs(grey["right"][155, 290] - 170) > 20  # and left
    plain = Renderer(get_world(track), rig="classic").render(Pose(x, y, h))
    assert not np.array_equal(plain, frames["center"])

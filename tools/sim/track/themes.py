"""Scenery themes as data: ground palettes, sky and haze colours, far terrain, trees, view distance.

One table per theme so that adding a theme is adding data, not code. ``meadow`` and ``forest`` are
the version-1 themes and their values must never change (version-1 tracks render byte for byte as
before); the others came with track format version 2.
"""

from __future__ import annotations

from dataclasses import dataclass

RGB = tuple[int, int, int]

#: Colours every theme shares unless it overrides them (version-2 surfaces and markings).
COMMON: dict[str, RGB] = {
    "asphalt": (92, 92, 96), "line": (232, 232, 226), "yellow": (226, 186, 48),
    "kerb_red": (196, 44, 38), "kerb_white": (230, 230, 226),
    "deck": (138, 100, 66), "deck2": (118, 84, 54), "gap": (58, 42, 30), "beam": (96, 74, 56),
    "dirt": (150, 122, 88), "rut": (118, 96, 70),
    "concrete": (158, 156, 150), "joint": (104, 102, 98),
    "gravel": (142, 134, 118), "gravel2": (126, 119, 104),
    "worn": (112, 110, 108), "patch": (70, 70, 74),
    "verge_grass": (84, 120, 54), "verge_sand": (188, 170, 128), "verge_dirt": (128, 104, 76),
    "verge_gravel": (136, 130, 120), "verge_concrete": (150, 166, 172),
}

# RGB albedo palettes (values before lighting; lighting at the default sun keeps them near these)
PALETTES: dict[str, dict[str, RGB]] = {
    "meadow": {**COMMON, "ground": (78, 128, 52), "ground2": (112, 138, 60), "shoulder": (132, 112, 84),
               "asphalt": (92, 92, 96), "line": (232, 232, 226), "dash": (232, 200, 60),
               "shore": (150, 138, 100), "water": (48, 86, 112), "deck": (138, 100, 66), "deck2": (118, 84, 54),
               "gap": (58, 42, 30), "beam": (96, 74, 56), "dirt": (150, 122, 88), "rut": (118, 96, 70),
               "kerb_red": (196, 44, 38), "kerb_white": (230, 230, 226)},
    "forest": {**COMMON, "ground": (58, 82, 40), "ground2": (96, 84, 52), "shoulder": (118, 108, 92),
               "asphalt": (84, 84, 88), "line": (228, 228, 222), "dash": (228, 228, 222),
               "shore": (110, 100, 76), "water": (40, 70, 84), "deck": (130, 96, 64), "deck2": (110, 80, 52),
               "gap": (50, 38, 28), "beam": (90, 70, 52), "dirt": (138, 112, 80), "rut": (108, 88, 64),
               "kerb_red": (196, 44, 38), "kerb_white": (230, 230, 226)},
    "desert": {**COMMON, "ground": (196, 166, 120), "ground2": (172, 136, 96), "shoulder": (180, 150, 110),
               "dash": (226, 186, 48), "shore": (170, 150, 110), "water": (56, 104, 120),
               "asphalt": (98, 94, 92), "dirt": (176, 140, 100), "rut": (150, 118, 84)},
    "autumn": {**COMMON, "ground": (124, 118, 56), "ground2": (150, 108, 52), "shoulder": (128, 104, 78),
               "dash": (232, 232, 226), "shore": (132, 118, 88), "water": (44, 74, 92)},
    "snow": {**COMMON, "ground": (226, 230, 236), "ground2": (204, 210, 220), "shoulder": (176, 176, 180),
             "dash": (226, 186, 48), "shore": (188, 192, 198), "water": (70, 92, 110),
             "asphalt": (78, 78, 82), "dirt": (130, 118, 104), "rut": (104, 94, 84),
             "verge_grass": (196, 202, 210)},
    "rocky": {**COMMON, "ground": (128, 120, 104), "ground2": (100, 96, 86), "shoulder": (136, 126, 110),
              "dash": (232, 232, 226), "shore": (120, 114, 100), "water": (46, 80, 96),
              "verge_grass": (104, 112, 70)},
    "wetland": {**COMMON, "ground": (70, 118, 60), "ground2": (96, 126, 64), "shoulder": (120, 106, 82),
                "dash": (232, 200, 60), "shore": (112, 112, 80), "water": (44, 82, 100)},
    # The real Udacity simulator's three tracks, as seen on public recordings of them (median colours of
    # the frames' regions: `docs/simulator.md`, "Udacity-like themes"); drawn only from procedural
    # noise, no texture or image of the Unity project or of a recording.
    "udacity_lake": {**COMMON, "ground": (176, 138, 83), "ground2": (150, 144, 78), "shoulder": (150, 166, 172),
                     "asphalt": (128, 130, 122), "yellow": (182, 159, 80), "dash": (182, 159, 80),
                     "shore": (168, 150, 110), "water": (70, 112, 142), "kerb_red": (225, 109, 101),
                     "kerb_white": (236, 236, 230), "dirt": (176, 138, 83), "rut": (150, 116, 72)},
    "udacity_jungle": {**COMMON, "ground": (104, 118, 66), "ground2": (86, 104, 52), "shoulder": (112, 122, 77),
                       "asphalt": (152, 151, 148), "line": (236, 236, 232), "dash": (236, 236, 232),
                       "shore": (110, 112, 80), "water": (60, 92, 100), "kerb_red": (232, 113, 115),
                       "verge_grass": (112, 122, 77)},
    "udacity_mountain": {**COMMON, "ground": (119, 92, 53), "ground2": (140, 110, 48), "shoulder": (139, 111, 48),
                         "asphalt": (62, 60, 60), "line": (200, 200, 196), "yellow": (139, 111, 48),
                         "dash": (139, 111, 48), "shore": (96, 86, 70), "water": (40, 60, 72),
                         "verge_dirt": (119, 92, 53)},
}


@dataclass(frozen=True)
class Ridge:
    """One silhouette layer of the far terrain in the sky panorama (heights in degrees)."""

    base: float
    amp: float
    harmonics: tuple[int, ...]
    color: RGB
    fade: float  # share of the haze colour (aerial perspective)
    jag: float = 0.0  # tree tops: small periodic spikes


@dataclass(frozen=True)
class SkyTheme:
    haze: RGB
    zenith: RGB
    ridges: tuple[Ridge, ...]


_MEADOW_RIDGES = (Ridge(0.6, 2.5, (2, 3, 5, 11), (104, 136, 110), 0.45),  # low hills
                  Ridge(0.2, 0.8, (7, 13, 29), (52, 84, 50), 0.3, jag=0.6))  # tree line
_FOREST_RIDGES = (Ridge(3.0, 9.0, (2, 3, 5, 9, 17, 31), (128, 146, 168), 0.35),  # far range
                  Ridge(1.5, 5.0, (3, 4, 7, 13, 27), (82, 104, 92), 0.3),  # nearer wooded range
                  Ridge(0.4, 1.2, (5, 11, 23), (38, 62, 38), 0.25, jag=0.8))  # forest edge

SKIES: dict[str, SkyTheme] = {
    "meadow": SkyTheme((200, 214, 224), (72, 128, 204), _MEADOW_RIDGES),
    "forest": SkyTheme((176, 190, 200), (84, 132, 190), _FOREST_RIDGES),
    "desert": SkyTheme((226, 216, 200), (86, 136, 206), (
        Ridge(1.0, 6.0, (2, 3, 5, 7, 13), (186, 150, 120), 0.4),  # mesas
        Ridge(0.2, 1.0, (5, 11, 23), (170, 136, 100), 0.3))),
    "autumn": SkyTheme((204, 206, 206), (96, 134, 190), (
        Ridge(0.8, 3.5, (2, 3, 5, 11), (130, 120, 112), 0.45),
        Ridge(0.3, 1.0, (7, 13, 29), (150, 92, 40), 0.3, jag=0.7))),
    "snow": SkyTheme((214, 222, 232), (110, 146, 196), (
        Ridge(2.5, 10.0, (2, 3, 5, 9, 17, 31), (222, 228, 238), 0.3),  # snowy range
        Ridge(0.4, 1.4, (5, 11, 23), (40, 60, 52), 0.3, jag=0.8))),
    "rocky": SkyTheme((196, 204, 212), (80, 126, 196), (
        Ridge(3.0, 12.0, (2, 3, 5, 9, 17, 31, 53), (140, 136, 140), 0.35),  # bare peaks
        Ridge(1.0, 4.0, (3, 5, 11, 21), (110, 102, 92), 0.3))),
    "wetland": SkyTheme((196, 210, 218), (76, 126, 196), (
        Ridge(0.3, 1.2, (2, 3, 5, 11), (100, 128, 108), 0.5),
        Ridge(0.2, 0.7, (7, 13, 29), (50, 80, 52), 0.3, jag=0.5))),
    "udacity_lake": SkyTheme((172, 200, 222), (108, 138, 180), (
        Ridge(1.0, 4.0, (2, 3, 5, 9, 17), (150, 150, 128), 0.35),  # pale rocky hills
        Ridge(0.5, 2.5, (3, 5, 11, 23), (120, 112, 70), 0.15),  # nearer grassy mounds
        Ridge(0.3, 1.0, (7, 13, 29), (40, 58, 34), 0.2, jag=0.9))),  # pine tops
    "udacity_jungle": SkyTheme((168, 188, 200), (96, 132, 186), (
        Ridge(6.0, 14.0, (2, 3, 5, 9, 17, 31), (92, 106, 76), 0.2),  # green mountains close by
        Ridge(3.0, 9.0, (3, 5, 11, 21, 41), (58, 66, 48), 0.1),  # dark rock walls
        Ridge(0.6, 1.5, (7, 13, 29), (60, 90, 40), 0.1, jag=0.9))),
    "udacity_mountain": SkyTheme((170, 190, 214), (70, 110, 180), (
        Ridge(6.0, 16.0, (2, 3, 5, 9, 17, 31, 53), (72, 72, 76), 0.15),  # grey cliffs
        Ridge(2.0, 6.0, (3, 5, 11, 21), (130, 104, 56), 0.15),  # autumn slopes
        Ridge(0.4, 1.2, (7, 13, 29), (150, 100, 40), 0.1, jag=0.8))),
}


@dataclass(frozen=True)
class TreeTheme:
    """Trees of a theme. ``leaves`` per tree kind: one colour (varied in brightness by each tree's
    tint, as version 1 does) or two (blended by the tint: autumn reds to yellows)."""

    conifer_share: float
    boulder_share: float  # of the remaining trees, drawn as grey boulders on the ground
    view_distance: float  # metres; further props are left to the haze and panorama
    leaves: dict[int, tuple[RGB, ...]]


BOULDER_COLOURS: tuple[RGB, RGB] = ((118, 112, 104), (150, 144, 134))
TREES: dict[str, TreeTheme] = {
    "meadow": TreeTheme(0.15, 0.0, 110.0, {0: ((60, 102, 42),), 1: ((36, 72, 40),)}),
    "forest": TreeTheme(0.8, 0.0, 85.0, {0: ((60, 102, 42),), 1: ((36, 72, 40),)}),
    "desert": TreeTheme(0.0, 0.5, 120.0, {0: ((96, 110, 56), (124, 120, 70)), 1: ((70, 90, 50),)}),
    "autumn": TreeTheme(0.25, 0.0, 100.0, {0: ((176, 58, 28), (214, 162, 40)), 1: ((40, 70, 40),)}),
    "snow": TreeTheme(0.9, 0.0, 100.0, {0: ((88, 80, 70),), 1: ((34, 62, 44), (60, 80, 70))}),
    "rocky": TreeTheme(0.45, 0.6, 110.0, {0: ((72, 96, 48),), 1: ((40, 66, 44),)}),
    "wetland": TreeTheme(0.1, 0.0, 110.0, {0: ((66, 108, 46), (90, 116, 48)), 1: ((36, 72, 40),)}),
    "udacity_lake": TreeTheme(0.85, 0.3, 120.0, {0: ((96, 110, 50),), 1: ((40, 62, 36), (56, 74, 40))}),
    "udacity_jungle": TreeTheme(0.2, 0.4, 90.0, {0: ((70, 110, 40), (96, 126, 52)), 1: ((40, 70, 36),)}),
    "udacity_mountain": TreeTheme(0.3, 0.6, 100.0, {0: ((176, 110, 36), (206, 160, 50)), 1: ((48, 60, 40),)}),
}

THEMES = tuple(PALETTES)
V1_THEMES = ("meadow", "forest")
#: The look of the real simulator's tracks (its lake, jungle and old mountain track).
UDACITY_THEMES = ("udacity_lake", "udacity_jungle", "udacity_mountain")
#: What procedural worlds draw from unless asked otherwise (generator version 1's themes).
GENERIC_THEMES = tuple(t for t in THEMES if t not in UDACITY_THEMES)

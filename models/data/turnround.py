"""Where a recorded driver turned the car round: the rows training leaves out (``drop_turnround``) and the stretches
the closed-loop measure hands to the person (:func:`tools.drivelog.path.reversing`), found by one rule.

Why training drops them: the Udacity log's speed has no sign, so a reversing car's rows pair the picture with
the wheel turned the way a car going backwards needs, the opposite of what the same picture asks of a car going
forwards; and the leg forwards at full lock that completes the turn is a U-turn, not the road's bend. Such rows
are few (about 1 % of the public recordings) but a large share of the full-lock rows (18 % in one
cross-validation fold), which steering-balanced sampling weighs up.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from protocol.datalog import Sample
from protocol.stamps import frame_time, session_ids
from protocol.units import SpeedUnit, to_kmh

#: Frame intervals beyond this are a pause (or a restart) of the recording: a new session starts.
SESSION_GAP_S = 1.0
#: Frame interval assumed where the names carry no time stamps (the simulator records at about 10 Hz).
DEFAULT_DT_S = 0.1
#: The recorded car reverses where its speed rises for at least this many frames running with the brake
#: pressed: the log's speed is unsigned, and the Udacity car brakes only while it rolls forward faster than
#: 5 mph; standing or rolling back, the brake key drives it backwards (its CarController's reverse torque).
#: Braking forward only ever slows the car; three frames (0.3 s) keep a moment's jitter of the speed out.
REVERSE_MIN_FRAMES = 3
#: ... and the speed rises by at least this much over them (m/s; reversing from a standstill gains about
#: 0.15 m/s a frame, the least rise seen under the brake on a forward slope was 0.05 m/s over 3 frames).
REVERSE_MIN_GAIN_MPS = 0.4
#: Turning round ends with a leg forwards at full lock (|steering| at least this; keyboard ramps reach 1.0 in 3
#: frames): the person who reversed completes the turn and hands back once the wheel comes off the lock.
REVERSE_LEG_LOCK = 0.9


def log_timing(samples: Sequence[Sample]) -> tuple[np.ndarray, np.ndarray]:
    """(session id, seconds to the next frame of the same session; 0 at a session's last frame) per row, from the
    frames' time stamps."""
    times = [frame_time(s.center) for s in samples]
    session = np.array(session_ids(times, SESSION_GAP_S), np.int64)
    dt = np.full(len(samples), DEFAULT_DT_S)
    for i in range(len(samples) - 1):
        a, b = times[i], times[i + 1]
        if a is not None and b is not None and session[i] == session[i + 1]:
            dt[i] = min(max(b - a, 0.0), SESSION_GAP_S)
    if len(samples):
        dt[np.r_[session[1:] != session[:-1], True]] = 0.0
    return session, dt


def turning_round(steering: np.ndarray, speed_mps: np.ndarray, brake: np.ndarray, dt: np.ndarray,
                  session: np.ndarray) -> np.ndarray:
    """Per row: the driver was turning round: reversing (standing just before, rolling back just after it) and
    the leg forwards at full lock that completes the turn.

    A car whose speed rises with the brake pressed is reversing (:data:`REVERSE_MIN_FRAMES`,
    :data:`REVERSE_MIN_GAIN_MPS`); the stretch runs back to the standstill it started from, and on while the brake
    is held and until the car, the brake let go, has stopped rolling back (the speed's lowest point on either
    side, within the session), and on while the wheel stays at full lock (:data:`REVERSE_LEG_LOCK`)."""
    n = len(speed_mps)
    out = np.zeros(n, bool)
    if n < 2:
        return out
    rising = np.r_[(brake[:-1] > 0) & (np.diff(speed_mps) > 0) & (dt[:-1] > 0), False]
    start = None
    for i, flag in enumerate([*rising, False]):
        if flag and start is None:
            start = i
        elif not flag and start is not None:
            end = i  # the frame the rise ended at
            if end - start >= REVERSE_MIN_FRAMES and speed_mps[end] - speed_mps[start] >= REVERSE_MIN_GAIN_MPS:
                a, b = start, end
                while a > 0 and session[a - 1] == session[a] and speed_mps[a - 1] <= speed_mps[a]:
                    a -= 1  # back to the standstill it started from
                while b + 1 < n and session[b + 1] == session[b] and (
                        speed_mps[b + 1] <= speed_mps[b] or brake[b] > 0):
                    b += 1  # on while the brake drives it backwards, and until it has stopped rolling back
                while b + 1 < n and session[b + 1] == session[b] and abs(steering[b + 1]) >= REVERSE_LEG_LOCK:
                    b += 1  # the leg forwards at full lock that completes the turn
                out[a:b + 1] = True
            start = None
    return out


def turnround_rows(samples: Sequence[Sample], speed_unit: SpeedUnit | str = SpeedUnit.MPH) -> np.ndarray:
    """:func:`turning_round` of one log's rows (in log order)."""
    session, dt = log_timing(samples)
    speed = to_kmh(np.array([s.speed for s in samples], np.float64), speed_unit) / 3.6
    return turning_round(np.array([s.steering for s in samples], np.float64), speed,
                         np.array([s.brake for s in samples], np.float64), dt, session)

"""Clock offsets between a log and a ground-truth file: found from the robot's turns, which every frame
agrees on (a rotation increment does not depend on where the map's origin is, nor on odometry drift in
position).

``estimate_clock_offset`` cross-correlates the two yaw rates on a common grid (any offset, found in one
FFT), then refines the best lag to a millisecond by comparing the ground truth's yaw increments between
consecutive poses with the log's odometry over the same, shifted, intervals.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from irmcl_warp.geometry import wrap_angle


@dataclass(frozen=True)
class ClockOffset:
    offset_s: float  # add to the ground truth's stamps to get the log's clock
    yaw_increment_error_deg: float  # median |d yaw(gt) - d yaw(odometry)| between consecutive poses, after the shift
    compared: int  # ground-truth steps compared at that offset
    contrast: float  # the error over steps of ten scan periods, over its median at offsets 5 to 60 s away: small
    #                  when the turns line up
    yaw_increment_error_at_zero_deg: float = float("nan")  # the same median with the stamps as they are

    @property
    def convincing(self) -> bool:
        """The turns agree after the shift far better than a few seconds off it (contrast on intel, fr079 and a
        simulated log: 0.04-0.12; ground truth whose stamps carry no information: near 1)."""
        return self.compared >= 20 and self.contrast < 0.3


def _yaw_rate(stamps, yaw, t0, dt, n):
    grid = t0 + dt * np.arange(n)
    y = np.interp(grid, stamps, np.unwrap(yaw))
    rate = np.gradient(y, dt)
    return rate - rate.mean()


def _step_errors(log_t, log_yaw_unwrapped, gt_t, gt_yaw, offset) -> np.ndarray:
    """|yaw step of the poses - the odometry's over the same steps shifted by ``offset``| (radians), per step whose
    shifted ends lie inside the log."""
    shifted = gt_t + offset
    ok = (shifted[:-1] >= log_t[0]) & (shifted[1:] <= log_t[-1])
    d_log = np.diff(np.interp(shifted, log_t, log_yaw_unwrapped))[ok]
    d_gt = wrap_angle(np.diff(gt_yaw))[ok]
    return np.abs(wrap_angle(d_gt - d_log))


def _increment_error(log_t, log_yaw_unwrapped, gt_t, gt_yaw, offset):
    """(the median of ``_step_errors`` in degrees, the steps compared); (inf, 0) with none."""
    e = _step_errors(log_t, log_yaw_unwrapped, gt_t, gt_yaw, offset)
    if len(e) == 0:
        return np.inf, 0
    return float(np.degrees(np.median(e))), int(len(e))


def estimate_clock_offset(
    log_stamps, log_odom, gt_stamps, gt_poses, min_overlap: float = 0.3, max_offset_s: float | None = None
) -> ClockOffset:
    """The offset to add to ``gt_stamps`` so that the ground truth's turns coincide with the odometry's (within
    ``max_offset_s`` of zero when given: a lag between two streams of one recording, where a drive that repeats
    itself must not line up a lap later)."""
    lt, gt = np.asarray(log_stamps, np.float64), np.asarray(gt_stamps, np.float64)
    lo, go = np.argsort(lt, kind="stable"), np.argsort(gt, kind="stable")
    lt, lyaw = lt[lo], np.asarray(log_odom, np.float64)[lo, 2]
    gt, gyaw = gt[go], np.asarray(gt_poses, np.float64)[go, 2]
    # a grid no finer than the sparser of the two, so keyframe ground truth is not read between its poses
    dt = max(
        0.05,
        0.5 * float(np.median(np.diff(gt))) if len(gt) > 1 else 0.05,
        float(np.median(np.diff(lt))) if len(lt) > 1 else 0.05,
    )
    na, nb = int((lt[-1] - lt[0]) / dt) + 1, int((gt[-1] - gt[0]) / dt) + 1
    a, b = _yaw_rate(lt, lyaw, lt[0], dt, na), _yaw_rate(gt, gyaw, gt[0], dt, nb)
    n = 1 << int(np.ceil(np.log2(na + nb)))
    corr = np.fft.irfft(np.fft.rfft(a, n) * np.conj(np.fft.rfft(b, n)), n)  # corr[k] = sum_i a[i + k] b[i]
    lags = np.concatenate([np.arange(0, na), np.arange(-nb + 1, 0)])
    values = np.concatenate([corr[:na], corr[n - nb + 1 :]])
    overlap = np.minimum(na, lags + nb) - np.maximum(0, lags)
    enough_overlap = overlap >= min_overlap * min(na, nb)
    if max_offset_s is not None:  # the offsets each lag stands for, kept near zero
        enough_overlap &= np.abs(lt[0] + lags * dt - gt[0]) <= max_offset_s + dt
    score = np.where(enough_overlap, values / np.maximum(overlap, 1), -np.inf)
    k = int(lags[np.argmax(score)])
    coarse = lt[0] + k * dt - gt[0]
    # refine: the offset whose shifted ground-truth steps turn like the odometry, to a millisecond; a dense
    # trajectory is compared over steps no shorter than two of the log's (shorter ones turn too little to tell)
    period = float(np.median(np.diff(lt))) if len(lt) > 1 else 0.0
    g_t, g_yaw = _thinned(gt, gyaw, 2.0 * period)
    yaw_log = np.unwrap(lyaw)
    best = (np.inf, 0, coarse)
    for span, step in ((2 * dt, dt / 20), (dt / 10, 1e-3)):
        centre = best[2]
        for off in centre + np.arange(-span, span + step / 2, step):
            err, m = _increment_error(lt, yaw_log, g_t, g_yaw, off)
            if err < best[0]:
                best = (err, m, off)
    # is the offset real? judged over steps of ten scan periods, where a turn outgrows the odometry's noise
    # (its random walk grows as the root of the step, the turn as the step): on a simulated log with noisy
    # odometry the contrast falls from 0.37 over two periods to 0.08, on fr079 from 0.10 to 0.04
    c_t, c_yaw = _thinned(gt, gyaw, 10.0 * period)
    here, _ = _increment_error(lt, yaw_log, c_t, c_yaw, best[2])
    away = [_increment_error(lt, yaw_log, c_t, c_yaw, best[2] + d) for d in (-60, -30, -10, -5, 5, 10, 30, 60)]
    away = [e for e, m in away if m >= 10]
    contrast = here / float(np.median(away)) if away and np.median(away) > 0 else 1.0
    at_zero, _ = _increment_error(lt, yaw_log, g_t, g_yaw, 0.0)
    return ClockOffset(float(best[2]), float(best[0]), int(best[1]), float(contrast), float(at_zero))


SCAN_LAG_MAX_S = 2.0  # the lags looked for between a recording's scans and its odometry
SCAN_LAG_MIN_S = 0.05  # a lag below this is not reported: a 100 deg/s turn moves 5 deg in it, half of RIGHT_DEG
SCAN_LAG_P = 1e-3  # ... nor one whose gain a held-out half of the steps does not show at this level
SCAN_LAG_MIN_STEPS = 40  # steps each half needs
SCAN_LAG_MAX_RATIO = 0.85  # ... nor one that lowers the held-out half's mean step error by less than 15 %: the real
#                            logs' lags lower it to 0.40-0.73 of the error at the stamps (mit-csail, fr079, MIT Killian;
#                            their corrected poses and our GMapping's), the simulator's odometry, in time, to no less
#                            than 0.915 (80 drives), where the median alone is fooled by its flat minimum


@dataclass(frozen=True)
class ScanLag:
    lag_s: float  # the offset that lines the poses' turns up with the odometry's (all steps)
    error_deg: float  # the median yaw step error there
    error_at_zero_deg: float  # ... and at the stamps
    first_half_lag_s: float  # the lag found on the first half of the steps ...
    held_out_p: float  # ... and the one-sided Wilcoxon p that it lowers the second half's step errors
    held_out_ratio: float  # ... and their mean there over their mean at the stamps
    steps: int
    convincing: bool

    @property
    def named(self) -> bool:
        """A lag of at least SCAN_LAG_MIN_S, found alike on all the steps and on the first half (within
        SCAN_LAG_MIN_S), whose gain the second half shows (at SCAN_LAG_P, and by SCAN_LAG_MAX_RATIO)."""
        return (
            self.convincing
            and min(abs(self.lag_s), abs(self.first_half_lag_s)) >= SCAN_LAG_MIN_S
            and abs(self.lag_s - self.first_half_lag_s) < SCAN_LAG_MIN_S
            and self.held_out_p < SCAN_LAG_P
            and self.held_out_ratio <= SCAN_LAG_MAX_RATIO
        )


def scan_lag(log_stamps, log_odom, pose_stamps, poses) -> ScanLag | None:
    """The lag between poses stamped as the scans (each where its scan was taken) and the odometry, and whether it is
    real: the lag is found (``estimate_clock_offset`` within SCAN_LAG_MAX_S) on the first half of the pose steps, and
    its gain tested on the second half, step by step, against the stamps (a one-sided Wilcoxon test: a lag picked
    from noise shows no gain where it was not picked). None with too few steps. On the simulator, whose odometry is
    in time, shows no such gain held out (SCAN_LAG_MAX_RATIO); the Freiburg logs and MIT Killian hold out at p < 1e-4."""
    from scipy.stats import wilcoxon

    lt, t = np.asarray(log_stamps, np.float64), np.asarray(pose_stamps, np.float64)
    if len(t) < 3 or len(lt) < 3:
        return None
    lo, po = np.argsort(lt, kind="stable"), np.argsort(t, kind="stable")
    lt, odom, t, poses = lt[lo], np.asarray(log_odom, np.float64)[lo], t[po], np.asarray(poses, np.float64)[po]
    g_t, g_yaw = _thinned(t, poses[:, 2], 2.0 * float(np.median(np.diff(lt))))
    half = len(g_t) // 2
    if half < SCAN_LAG_MIN_STEPS:
        return None
    c = estimate_clock_offset(lt, odom, t, poses, max_offset_s=SCAN_LAG_MAX_S)
    first = estimate_clock_offset(
        lt, odom, g_t[:half], np.column_stack([np.zeros((half, 2)), g_yaw[:half]]), max_offset_s=SCAN_LAG_MAX_S
    )
    yaw_u = np.unwrap(odom[:, 2])
    at_zero = _step_errors(lt, yaw_u, g_t[half:], g_yaw[half:], 0.0)
    at_lag = _step_errors(lt, yaw_u, g_t[half:], g_yaw[half:], first.offset_s)
    n = min(len(at_zero), len(at_lag))
    diff = at_zero[:n] - at_lag[:n]
    p = float(wilcoxon(diff, alternative="greater").pvalue) if np.any(diff != 0) else 1.0
    ratio = float(np.mean(at_lag[:n]) / np.mean(at_zero[:n])) if np.mean(at_zero[:n]) > 0 else 1.0
    return ScanLag(
        c.offset_s,
        c.yaw_increment_error_deg,
        c.yaw_increment_error_at_zero_deg,
        first.offset_s,
        p,
        ratio,
        n,
        c.convincing,
    )


def scan_lag_note(
    log_stamps, log_odom, pose_stamps, poses, applied_s: float = 0.0, lag: ScanLag | None = None
) -> str | None:
    """Poses stamped as the scans (matched to them by stamp: each is where its scan was taken) that turn like the
    odometry at another time say that the scans' stamps and the odometry's clock differ: the odometry a reader
    gives each scan then belongs to another moment, and every turn puts the scan's heading off by the turn rate times
    the lag (mit-csail's bag and CARMEN log, fr079's: the scans read ~0.13 s late, 13 deg at 100 deg/s). Returns a
    sentence naming the lag and the setting that removes it (``data.scan_time_offset_s``, ``applied_s`` being the one
    already applied), or None unless ``scan_lag`` names one (at least SCAN_LAG_MIN_S, held out at SCAN_LAG_P; ``lag``:
    its result, when already found)."""
    lag = lag or scan_lag(log_stamps, log_odom, pose_stamps, poses)
    if lag is None or not lag.named:
        return None
    late = "late" if lag.lag_s < 0 else "early"
    return (
        f"the poses stamped as its scans turn as its odometry did {abs(lag.lag_s):.3f} s "
        f"{'earlier' if lag.lag_s < 0 else 'later'}: the scans appear stamped {abs(lag.lag_s):.3f} s {late} "
        f"against the odometry's clock (yaw steps agree with the odometry to {lag.error_deg:.2f} deg there, "
        f"{lag.error_at_zero_deg:.2f} deg at the stamps; held out, {100 * (1 - lag.held_out_ratio):.0f} % lower, "
        f"p = {lag.held_out_p:.1g}), so each scan's odometry "
        f"is read at another moment and turns put its heading off; set data.scan_time_offset_s={applied_s + lag.lag_s:.3f}"
    )


def _thinned(stamps, yaw, min_step: float):
    """The poses at least ``min_step`` apart (all of them for keyframes already sparser)."""
    if min_step <= 0:
        return stamps, yaw
    keep = np.concatenate([[True], np.diff(np.floor((stamps - stamps[0]) / min_step)) > 0])
    return stamps[keep], yaw[keep]

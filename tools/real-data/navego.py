"""NaveGo's planetary-rover example data (rodralez/NaveGo `examples/visual-data/`, built from two
public rover data sets by J. Diep's scripts there, `*-planetary-data/scripts/*_structure.m`):

- `canada-planetary-data/`: run 3 of the Canadian Planetary Emulation Terrain Energy-Aware Rover
  Navigation dataset (O. Lamarre, O. Limoyo, F. Maric, J. Kelly, STARS Laboratory, University of
  Toronto): a Clearpath Husky on the Canadian Space Agency's Mars Emulation Terrain. The reference
  is the data set's `global-pose-utm.txt` (UTM zone 18T), interpolated to 20 Hz.
- `katwijk-planetary-data/`: 300 s of the Katwijk Beach Planetary Rover Dataset (ESA's HDPR rover
  on a beach at Katwijk); the reference is its `gps-latlong.txt`, interpolated to 5 Hz.

Files: `data/imu_planetary.mat`, a 1 x 1 struct `imu_planetary` with `t` (s, N x 1), `fb`
(specific force, m/s^2, N x 3) and `wb` (angular rate, rad/s, N x 3); `t` is not the logged
time: the script rebuilds it as a uniform grid from the first stamp at the mean step.
`data/gnss_planetary_r.mat`, a 1 x 1 struct `gnss_planetary_r` with `t` (s), `lat` and `lon`
(rad); `gnss_planetary.mat` beside it is the same track with 5 m of noise added on purpose (not
a truth, not read).

Both times start at their own first row: the two logs are not synchronised in these files. The
offset is measured here, as the lag that best correlates the IMU's yaw rate about its start-up
up axis (the mean specific force of its first 0.5 s, when both rovers stand still) with the
reference track's
counter-clockwise heading rate (BIN_S bins, lags within MAX_LAG_S), so that the truth can count
from the pose where the odometry aligns. That the best correlation is positive (at least MIN_R)
also checks the axes: a right-handed sensor frame measuring specific force turns with the track
about its up axis; a left-handed frame, or acceleration with gravity's sign, would correlate
negatively and is refused. The samples pass through unchanged.
"""

import math
import statistics

from containers import ConvertError, mat_matrix

G0 = 9.80665  # m/s^2 per g
DEG = 180.0 / math.pi
BIN_S = 4.0  # yaw-rate bins for the clock offset, s (shorter bins are dominated by the chords' noise)
LAG_STEP_S = 0.5  # step of the offsets searched, s
MAX_LAG_S = 20.0  # the offsets searched, s
MIN_R = 0.4  # the correlation below which no offset is taken
MIN_SPEED_MPS = 0.15  # slower chords give no heading
TRACK_MIN_STEP_M = 0.1  # the truth's track length counts steps of at least this much (noise at rest adds none)


def _column(arrays, name, where, width):
    rows = mat_matrix(arrays, name, where)
    if not rows or len(rows[0]) != width:
        raise ConvertError(where, None, name, f"expected N x {width}, got {len(rows)} x {len(rows[0]) if rows else 0}")
    for i, row in enumerate(rows):
        if not all(math.isfinite(v) for v in row):
            raise ConvertError(where, None, name, f"row {i} (0-based) is not finite")
    return rows


def samples(arrays, where):
    """(samples, notes): canonical samples (t s, specific force g, angular rate deg/s) from the
    `imu_planetary` struct."""
    t = [r[0] for r in _column(arrays, "imu_planetary.t", where, 1)]
    fb = _column(arrays, "imu_planetary.fb", where, 3)
    wb = _column(arrays, "imu_planetary.wb", where, 3)
    if not (len(t) == len(fb) == len(wb)) or len(t) < 2:
        raise ConvertError(where, None, "imu_planetary.t", f"{len(t)} times for {len(fb)} and {len(wb)} samples")
    out = [(ti, f[0] / G0, f[1] / G0, f[2] / G0, w[0] * DEG, w[1] * DEG, w[2] * DEG) for ti, f, w in zip(t, fb, wb)]
    notes = ["imu_planetary.fb m/s^2 -> g (/9.80665), wb rad/s -> deg/s; t as NaveGo rebuilt it "
             "(a uniform grid at the mean step from the first stamp, imu_structure.m)"]
    return out, notes


def reference_fixes(arrays, where):
    """[(t s, latitude deg, longitude deg)] of the `gnss_planetary_r` struct."""
    t = [r[0] for r in _column(arrays, "gnss_planetary_r.t", where, 1)]
    lat = [r[0] for r in _column(arrays, "gnss_planetary_r.lat", where, 1)]
    lon = [r[0] for r in _column(arrays, "gnss_planetary_r.lon", where, 1)]
    if not (len(t) == len(lat) == len(lon)) or len(t) < 2:
        raise ConvertError(where, None, "gnss_planetary_r.t", f"{len(t)} times for {len(lat)} positions")
    return [(ti, la * DEG, lo * DEG) for ti, la, lo in zip(t, lat, lon)]


def _binned(values, times, t_end, bin_s=BIN_S):
    """Mean of `values` per `bin_s` bin from 0 to t_end (None where a bin holds none)."""
    sums, counts = {}, {}
    for t, v in zip(times, values):
        if v is not None and 0 <= t < t_end:
            k = int(t // bin_s)
            sums[k] = sums.get(k, 0.0) + v
            counts[k] = counts.get(k, 0) + 1
    return [sums[k] / counts[k] if k in counts else None for k in range(int(t_end // bin_s) + 1)]


def imu_yaw_rate(samples_):
    """(times, yaw rate rad/s about the up axis of the first 0.5 s's mean specific force)."""
    still = [s for s in samples_ if s[0] - samples_[0][0] < 0.5] or samples_[:1]
    up = [statistics.mean(s[i] for s in still) for i in (1, 2, 3)]
    norm = math.sqrt(sum(u * u for u in up))
    up = [u / norm for u in up]
    return [s[0] for s in samples_], [sum(s[4 + i] * up[i] for i in range(3)) / DEG for s in samples_]


def track_yaw_rate(track):
    """(times, heading rate rad/s, counter-clockwise) of a track from chords between the poses
    1 s either side of each (None where slower than MIN_SPEED_MPS)."""
    heads, lo, hi = [], 0, 0
    for t, _, _ in track:
        while lo + 1 < len(track) and t - track[lo + 1][0] >= 1.0:
            lo += 1
        while hi < len(track) and track[hi][0] - t < 1.0:
            hi += 1
        a, b = track[lo], track[hi] if hi < len(track) else None
        ok = b is not None and t - a[0] >= 1.0 and math.dist(a[1:], b[1:]) >= MIN_SPEED_MPS * (b[0] - a[0])
        heads.append((t, math.atan2(b[2] - a[2], b[1] - a[1]) if ok else None))
    times, rates = [], []
    for (t0, h0), (t1, h1) in zip(heads, heads[1:]):
        times.append(t0)
        rates.append(None if h0 is None or h1 is None else math.remainder(h1 - h0, 2 * math.pi) / (t1 - t0))
    return times, rates


def _correlation(xs, ys):
    pairs = [(x, y) for x, y in zip(xs, ys) if x is not None and y is not None]
    if len(pairs) < 20:
        return None
    mx, my = statistics.mean(p[0] for p in pairs), statistics.mean(p[1] for p in pairs)
    sxy = sum((x - mx) * (y - my) for x, y in pairs)
    sxx, syy = sum((x - mx) ** 2 for x, _ in pairs), sum((y - my) ** 2 for _, y in pairs)
    return sxy / math.sqrt(sxx * syy) if sxx > 0 and syy > 0 else None


def best_lag(imu, ref_times, ref_rates, t_end, max_lag_s, step_s, bin_s=BIN_S):
    """(lag s, r, the reference binned at that lag) where the reference rates (`ref_times`,
    `ref_rates` on its own clock), shifted by the lag and averaged over `bin_s` bins, best
    correlate (r) with the binned IMU rates `imu`; lags in `step_s` steps within `max_lag_s`.
    None if no lag gives a correlation."""
    best = None
    steps = int(round(max_lag_s / step_s))
    for k in range(-steps, steps + 1):
        ref = _binned(ref_rates, [t + k * step_s for t in ref_times], t_end, bin_s)
        r = _correlation(imu, ref)
        if r is not None and (best is None or r > best[1]):
            best = (k * step_s, r, ref)
    return best


def rate_lag(imu_times, imu_rates, ref_times, ref_rates, bin_s, step_s, max_lag_s):
    """(lag s, r, slope), or (None, None, None) where no lag correlates: IMU time = reference
    time + lag (steps of `step_s` within `max_lag_s`) where the IMU's rates, averaged over `bin_s`
    bins from time 0, best correlate (r) with the reference's; slope is the IMU's rate over the
    reference's at that lag (least squares through 0), near 1 when both are in the same unit."""
    t_end = max(imu_times[-1], ref_times[-1]) + max_lag_s
    imu = _binned(imu_rates, imu_times, t_end, bin_s)
    best = best_lag(imu, ref_times, ref_rates, t_end, max_lag_s, step_s, bin_s)
    if best is None:
        return None, None, None
    pairs = [(a, b) for a, b in zip(imu, best[2]) if a is not None and b is not None]
    return best[0], best[1], sum(a * b for a, b in pairs) / sum(b * b for _, b in pairs)


def yaw_rate_lag(samples_, track, bin_s, step_s, max_lag_s):
    """[`rate_lag`] of the IMU's yaw rate about its start-up up axis against the track's heading
    rate (rad/s both): a slope near 1 when the gyro is in deg/s about a right-handed frame."""
    return rate_lag(*imu_yaw_rate(samples_), *track_yaw_rate(track), bin_s, step_s, max_lag_s)


def clock_offset(samples_, track, where):
    """(offset s, r): IMU time = reference time + offset, the lag (LAG_STEP_S steps within
    MAX_LAG_S) where the IMU's yaw rate about its start-up up axis, averaged over BIN_S bins,
    best correlates (r) with the track's heading rate (a constant gyro bias does not change r).
    A ConvertError if no lag correlates at r >= MIN_R."""
    lag, r, _ = yaw_rate_lag(samples_, track, BIN_S, LAG_STEP_S, MAX_LAG_S)
    if r is None or r < MIN_R:
        raise ConvertError(where, None, "gnss_planetary_r.t",
                           f"no clock offset within {MAX_LAG_S} s correlates the yaw rates (best {lag}, r {r})")
    return lag, r


def track_truth(track, offset, r):
    """The truth: the reference track on the IMU's clock (`track`: [t_s, east, north]) and the
    last pose's distance from the first. Our heading is fixed at alignment, not north: only
    distances are a truth."""
    end = [track[-1][1] - track[0][1], track[-1][2] - track[0][2]]
    return {
        "kind": "reference_track",
        "frame": "unknown_heading",
        "end_displacement_m": None,
        "end_distance_m": math.hypot(*end),
        "end_displacement_enu_m": end,
        "poses": len(track),
        "clock_offset_s": offset,
        "clock_offset_r": round(r, 3),
        "track": [[round(t + offset, 4), round(e, 4), round(n, 4)] for t, e, n in track],
        "track_min_step_m": TRACK_MIN_STEP_M,
        "source": "gnss_planetary_r (the data set's reference positions as NaveGo interpolated them, corpus.json) on "
                  "the IMU's clock shifted by clock_offset_s (measured from the yaw rates, navego.py); bench.py measures "
                  "from the pose at the odometry's alignment to the last; the heading is not ours, so only distances are a truth",
    }


def _mat_struct_arrays(name, columns):
    """{"name.field": (rows, cols, column-major values)} for mat_bytes, as read_mat flattens a
    1 x 1 struct's fields."""
    out = {}
    for field, rows in columns.items():
        out[f"{name}.{field}"] = (len(rows), len(rows[0]), [row[c] for c in range(len(rows[0])) for row in rows])
    return out


def self_test(local_east_north):
    """A rover weaving at 0.5 m/s with its IMU z down, the reference log starting 3 s after
    the IMU's: units, the offset, the truth; malformed input names the field. The caller
    passes its projection of (latitude, longitude) degrees to local (east, north) metres."""
    from containers import mat_bytes, read_mat

    def heading(t):
        return 0.6 * math.sin(0.15 * t) + 0.3 * math.sin(0.4 * t)

    def rate(t):
        return 0.09 * math.cos(0.15 * t) + 0.12 * math.cos(0.4 * t)

    imu_t = [i / 50 for i in range(50 * 120)]
    imu = _mat_struct_arrays("imu_planetary", {
        "t": [[t] for t in imu_t], "fb": [[0.0, 0.0, -G0] for _ in imu_t], "wb": [[0.0, 0.0, -rate(t)] for t in imu_t]})
    s, _ = samples(read_mat(mat_bytes(imu, True), "i.mat"), "i.mat")
    assert abs(s[0][3] + 1.0) < 1e-12 and abs(s[50][6] + rate(1.0) * DEG) < 1e-9, s[50]
    pos, lat0, lon0, track_rows = [0.0, 0.0], 0.7944, -1.2810, []
    for i in range(20 * 110):
        t = 3.0 + i / 20  # the reference's clock: 0 at IMU time 3 s
        pos = [pos[0] + 0.025 * math.cos(heading(t)), pos[1] + 0.025 * math.sin(heading(t))]
        track_rows.append((i / 20, lat0 + pos[1] / 6367000.0, lon0 + pos[0] / (6388000.0 * math.cos(lat0))))
    ref = _mat_struct_arrays("gnss_planetary_r", {"t": [[r[0]] for r in track_rows], "lat": [[r[1]] for r in track_rows],
                                                  "lon": [[r[2]] for r in track_rows]})
    fixes = reference_fixes(read_mat(mat_bytes(ref, False), "g.mat"), "g.mat")
    track = [(t, e, n) for (t, _, _), (e, n) in zip(fixes, local_east_north([f[1:] for f in fixes]))]
    offset, r = clock_offset(s, track, "g.mat")
    assert offset == 3.0 and r > 0.9, (offset, r)
    truth = track_truth(track, offset, r)
    assert truth["track"][0][0] == 3.0 and truth["track"][-1][0] == 3.0 + track[-1][0], truth["track"][-1]
    assert abs(truth["end_distance_m"] - math.hypot(*track[-1][1:])) < 1e-9, truth["end_distance_m"]
    bad = dict(imu, **{"imu_planetary.wb": (2, 3, [0.0] * 6)})
    try:
        samples(read_mat(mat_bytes(bad, False), "b.mat"), "b.mat")
    except ConvertError as e:
        assert "b.mat" in str(e) and "imu_planetary.t" in str(e), str(e)
    else:
        raise AssertionError("no error for mismatched lengths")
    return "navego_planetary_mat"

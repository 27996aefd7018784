// fleetcal dashboard: the drift of one LiDAR's mount over its accepted calibrations. A failed run
// is no calibration anyone uses: it never moves the headline nor enters the charts, it is only
// counted (and the newest one named) so that nobody wonders where it went. Pure functions, on
// `fleetcal.drift`.
"use strict";

(() => {
  // Rotation vector (deg, about the LiDAR's own axes) of q0^-1 q1: the change from q0 to q1.
  // Quaternions are [x, y, z, w].
  function rotationChangeDeg(q0, q1) {
    const [ax, ay, az, aw] = [-q0[0], -q0[1], -q0[2], q0[3]];
    const [bx, by, bz, bw] = q1;
    let x = aw * bx + ax * bw + ay * bz - az * by;
    let y = aw * by - ax * bz + ay * bw + az * bx;
    let z = aw * bz + ax * by - ay * bx + az * bw;
    let w = aw * bw - ax * bx - ay * by - az * bz;
    if (w < 0) [x, y, z, w] = [-x, -y, -z, -w];
    const norm = Math.hypot(x, y, z);
    if (norm < 1e-15) return [0, 0, 0];
    const angle = (2 * Math.atan2(norm, w) * 180) / Math.PI;
    return [x, y, z].map((c) => (c / norm) * angle);
  }

  // `points`: one LiDAR's history points (`/v1/robots/{id}/history`), oldest first. Returns
  // {base, latest, changes, translationMm, rotationDeg, failed, newestFailed}: the first and the
  // newest accepted calibrations (null when none), each accepted one's change from `base`
  // (dt: mm per base-frame axis, dr: deg about the LiDAR's axes), the drift of `latest`, and
  // the failed runs left out (with the newest of them, when it is newer than `latest`).
  function ofAccepted(points) {
    // In use: the verdict, unless an operator accepted or rejected the calibration.
    const inUse = (p) => p.accepted ?? p.passed;
    const accepted = points.filter(inUse);
    const failed = points.filter((p) => !inUse(p));
    const base = accepted[0] || null;
    const latest = accepted.at(-1) || null;
    const changes = accepted.map((p) => ({
      point: p,
      t: new Date(p.measured_at),
      dt: p.translation.map((v, k) => (v - base.translation[k]) * 1000),
      dr: rotationChangeDeg(base.rotation_xyzw, p.rotation_xyzw),
    }));
    const last = changes.at(-1);
    const newest = failed.at(-1);
    return {
      base,
      latest,
      changes,
      translationMm: last ? Math.hypot(...last.dt) : null,
      rotationDeg: last ? Math.hypot(...last.dr) : null,
      failed: failed.length,
      newestFailed: newest && (!latest || new Date(newest.measured_at) > new Date(latest.measured_at)) ? newest : null,
    };
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, { drift: { ofAccepted, rotationChangeDeg } });
})();

// fleetcal dashboard: axis ticks for the charts. Values get 1-2-5 steps; times get calendar
// steps (minutes to years, in local time) whose labels are never repeated: each label shows the
// resolution of its step, with the date when the ticks cross midnight. Pure functions, on
// `fleetcal.ticks`.
"use strict";

(() => {
  const MINUTE = 60e3, HOUR = 60 * MINUTE, DAY = 24 * HOUR;

  function values(lo, hi, count = 5) {
    const span = hi - lo || Math.abs(hi) || 1;
    const raw = span / count;
    const power = 10 ** Math.floor(Math.log10(raw));
    const step = [1, 2, 5, 10].map((m) => m * power).find((v) => v >= raw) || 10 * power;
    const ticks = [];
    for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) ticks.push(Number(v.toPrecision(12)));
    return ticks;
  }

  // Steps of the clock divide a day, so they line up across midnight; the others follow the
  // calendar. `ms` only sizes a step when choosing one.
  const clock = (ms) => ({
    unit: ms < HOUR ? "minute" : "hour",
    ms,
    floor: (t) => {
      const midnight = new Date(t).setHours(0, 0, 0, 0);
      return midnight + Math.floor((t - midnight) / ms) * ms;
    },
    next: (t) => t + ms,
  });
  const calendar = (unit, n, ms, floor, add) => ({ unit, ms: n * ms, floor: (t) => floor(new Date(t), n), next: (t) => add(new Date(t), n) });
  const days = (n) =>
    calendar("day", n, DAY, (d) => d.setHours(0, 0, 0, 0), (d, k) => d.setDate(d.getDate() + k));
  const months = (n) =>
    calendar("month", n, 30.44 * DAY, (d, k) => new Date(d.getFullYear(), Math.floor(d.getMonth() / k) * k, 1).getTime(), (d, k) => d.setMonth(d.getMonth() + k));
  const years = (n) =>
    calendar("year", n, 365.25 * DAY, (d, k) => new Date(Math.floor(d.getFullYear() / k) * k, 0, 1).getTime(), (d, k) => d.setFullYear(d.getFullYear() + k));
  const STEPS = [
    ...[1, 2, 5, 10, 15, 30].map((m) => clock(m * MINUTE)),
    ...[1, 2, 3, 6, 12].map((h) => clock(h * HOUR)),
    days(1), days(2), days(7), days(14),
    months(1), months(3), months(6),
    ...[1, 2, 5, 10, 20, 50, 100].map(years),
  ];

  const dayOf = (t) => new Date(t).toDateString();

  function label(t, unit, crossesMidnight, crossesYear) {
    const date = new Date(t);
    const time = date.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit" });
    const day = date.toLocaleDateString([], crossesYear ? { day: "numeric", month: "short", year: "numeric" } : { day: "numeric", month: "short" });
    if (unit === "minute" || unit === "hour") return crossesMidnight ? `${day} ${time}` : time;
    if (unit === "day") return day;
    if (unit === "month") return date.toLocaleDateString([], { month: "short", year: "numeric" });
    return String(date.getFullYear());
  }

  // The axis of times t0..t1 (ms since the epoch): {start, end, ticks: [{t, label}]}, where
  // start <= t0 and end >= t1 are ticks themselves, and at most about `most` ticks.
  function times(t0, t1, most = 6) {
    const span = Math.max(t1 - t0, 1);
    const step = STEPS.find((s) => span / s.ms <= most - 1) || STEPS.at(-1);
    const start = step.floor(t0);
    const at = [start];
    while (at.length < 2 || at.at(-1) < t1) at.push(step.next(at.at(-1)));
    const end = at.at(-1);
    const crossesMidnight = dayOf(start) !== dayOf(end);
    const crossesYear = new Date(start).getFullYear() !== new Date(end).getFullYear();
    return { start, end, unit: step.unit, ticks: at.map((t) => ({ t, label: label(t, step.unit, crossesMidnight, crossesYear) })) };
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, { ticks: { values, times } });
})();

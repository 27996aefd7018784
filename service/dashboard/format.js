// fleetcal dashboard: numbers as people read them, with their units and a precision that fits
// their size (never `22.00000` iterations or `0.00140` m). Pure functions, on `fleetcal.format`.
"use strict";

(() => {
  const missing = (value) => value === null || value === undefined || !Number.isFinite(value);

  // Millimetres: two decimals below 1 mm (stddev), one up to 100 mm, none up to a metre;
  // metres beyond.
  function mm(metres) {
    if (missing(metres)) return "–";
    if (Math.abs(metres) >= 1) return `${metres.toFixed(2)} m`;
    const value = metres * 1000;
    const size = Math.abs(value);
    const digits = size === 0 || size >= 100 ? 0 : size >= 1 ? 1 : 2;
    return `${value.toFixed(digits)} mm`;
  }

  // Degrees: three decimals below 1°, two up to 10°, one beyond.
  function deg(value) {
    if (missing(value)) return "–";
    const size = Math.abs(value);
    const digits = size === 0 ? 0 : size >= 10 ? 1 : size >= 1 ? 2 : 3;
    return `${value.toFixed(digits)}°`;
  }

  function count(value, unit) {
    return missing(value) ? "–" : `${Math.round(value).toLocaleString()} ${unit}`;
  }

  // Up to four significant digits, no trailing zeros: for values of no known unit.
  function plain(value) {
    return missing(value) ? "–" : String(Number(value.toPrecision(4)));
  }

  // Each verdict check by its name's kind (`<kind>:<frame>`): how its value and limit read, and
  // whether the limit is a most or a least.
  const CHECK_KINDS = {
    metric_error: { value: mm, bound: "≤" },
    seen_metric_error: { value: mm, bound: "≤" },
    convergence: { value: (v) => count(v, "iterations"), bound: "≤" },
    object_points: { value: (v) => count(v, "points"), bound: "≥" },
  };

  function checkKind(name) {
    const kind = name.split(":")[0];
    if (CHECK_KINDS[kind]) return CHECK_KINDS[kind];
    if (kind.endsWith("_translation")) return { value: mm, bound: "≤" };
    if (kind.endsWith("_rotation")) return { value: deg, bound: "≤" };
    return { value: plain, bound: "≤" };
  }

  // {value, limit}: the two cells of a check's row, as text.
  function checkCells(check) {
    if (check.name.startsWith("determined:")) {
      const dofs = check.dofs || [];
      return { value: dofs.length ? `undetermined: ${dofs.join(", ")}` : "all 6 DoF determined", limit: "none undetermined" };
    }
    const kind = checkKind(check.name);
    return {
      value: typeof check.value === "number" ? kind.value(check.value) : "–",
      limit: typeof check.limit === "number" ? `${kind.bound} ${kind.value(check.limit)}` : "–",
    };
  }

  // A LiDAR's 1-sigma in result.json: `stddev.translation_m` / `rotation_deg` per axis, null for
  // a degree of freedom the data did not determine (`undetermined` names them). A null must read
  // as undetermined, never vanish into the largest of the others.
  function stddevSummary(lidar, isReference) {
    if (isReference) return { text: "reference (defines the frame)", undetermined: [] };
    const sd = lidar.stddev || {};
    const names = ["x", "y", "z", "roll", "pitch", "yaw"];
    const values = [...(sd.translation_m || [null, null, null]), ...(sd.rotation_deg || [null, null, null])];
    const undetermined = [...new Set([...(lidar.undetermined || []), ...names.filter((_, k) => missing(values[k]))])];
    const known = (from, to) => values.slice(from, to).filter((v) => !missing(v));
    const translation = known(0, 3), rotation = known(3, 6);
    const parts = [];
    if (translation.length) parts.push(`${mm(Math.max(...translation))}`);
    if (rotation.length) parts.push(`${deg(Math.max(...rotation))}`);
    const largest = parts.length ? `up to ${parts.join(", ")}` : "";
    return { text: largest, undetermined: names.filter((name) => undetermined.includes(name)) };
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, {
    format: { mm, deg, count, plain, checkCells, stddevSummary },
  });
})();

// fleetcal dashboard: a small client of the /v1 API, no build step and no dependencies.
// Pages (hash routes): #/ fleet overview, #/robots/<id> one robot's history, #/runs/<id> one run;
// compare.js draws #/robots/<id>/compare and webhooks.js #/webhooks (admin keys).
"use strict";

(() => {
  // The report images' colours (pipeline.report.LIDAR_COLOURS): LiDAR i, the reference first.
  const COLOURS = ["#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9", "#000000", "#F0E442"];
  const AXIS_COLOURS = ["#D55E00", "#009E73", "#0072B2"]; // x, y, z
  const POLL_MS = 1000;
  const app = document.getElementById("app");
  const forgetButton = document.getElementById("forget-key");
  const navWebhooks = document.getElementById("nav-webhooks");
  const keyName = document.getElementById("key-name");
  let generation = 0; // bumped on every navigation: stale loads and polls stop drawing
  let blobUrls = [];

  // api.js and ui.js (loaded first) call the API and build elements; this file draws pages.
  const { KEY_STORAGE, ApiError, request, api, saveBlob, qs, access } = fleetcal.api;
  const { h, s, show, setCrumbs, fact, ago, when, shortId, statusBadge, verdictBadge, acceptedBadge, swatch, downloadButton } = fleetcal.ui;

  async function blobUrl(path) {
    const url = URL.createObjectURL(await (await request(path)).blob());
    blobUrls.push(url);
    return url;
  }

  // -- formatting -------------------------------------------------------------------------------

  // format.js, ticks.js and drift.js (loaded first) hold the pure logic; this file draws pages.
  const { mm, deg, checkCells, stddevSummary } = fleetcal.format;
  const { ofAccepted, rotationChangeDeg } = fleetcal.drift;

  // -- charts (inline SVG) ----------------------------------------------------------------------

  // series: [{label, colour, points: [{t: Date, v, passed, runId}]}]; band: {lo, hi, label} or null.
  function timeChart({ id, title, unit, series, band, note }) {
    const W = 640, H = 230, L = 60, R = 14, T = 12, B = 34;
    const points = series.flatMap((x) => x.points);
    const times = points.map((p) => p.t.getTime());
    const first = Math.min(...times), last = Math.max(...times);
    const around = first === last ? 3600e3 : 0; // one calibration: an hour either side of it
    const axis = fleetcal.ticks.times(first - around, last + around);
    const t0 = axis.start, t1 = axis.end;
    const values = points.map((p) => p.v).concat(band ? [band.lo, band.hi] : []);
    let v0 = Math.min(...values), v1 = Math.max(...values);
    const pad = (v1 - v0) * 0.12 || Math.abs(v1) * 0.2 || 1;
    v0 -= pad;
    v1 += pad;
    const x = (t) => L + ((t - t0) / (t1 - t0)) * (W - L - R);
    const y = (v) => T + (1 - (v - v0) / (v1 - v0)) * (H - T - B);
    const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, class: "chart", role: "img", "aria-label": title, dataset: { points: points.length } });
    if (band) {
      svg.append(
        s("rect", { class: "band", x: L, y: y(band.hi), width: W - L - R, height: Math.max(0, y(band.lo) - y(band.hi)) }),
        s("line", { class: "band-edge", x1: L, x2: W - R, y1: y(band.hi), y2: y(band.hi) }),
        s("line", { class: "band-edge", x1: L, x2: W - R, y1: y(band.lo), y2: y(band.lo) }),
        s("text", { class: "band-label", x: W - R - 4, y: y(band.hi) - 4, "text-anchor": "end" }, band.label),
      );
    }
    for (const v of fleetcal.ticks.values(v0, v1)) {
      svg.append(
        s("line", { class: "grid", x1: L, x2: W - R, y1: y(v), y2: y(v) }),
        s("text", { class: "tick", x: L - 6, y: y(v) + 4, "text-anchor": "end" }, `${v}`),
      );
    }
    axis.ticks.forEach(({ t, label }, k) => {
      const anchor = k === 0 ? "start" : k === axis.ticks.length - 1 ? "end" : "middle";
      svg.append(s("text", { class: "tick time-tick", x: x(t), y: H - B + 16, "text-anchor": anchor }, label));
    });
    svg.append(
      s("line", { class: "axis", x1: L, x2: L, y1: T, y2: H - B }),
      s("line", { class: "axis", x1: L, x2: W - R, y1: H - B, y2: H - B }),
      s("text", { class: "unit", x: 12, y: T + (H - T - B) / 2, transform: `rotate(-90 12 ${T + (H - T - B) / 2})`, "text-anchor": "middle" }, unit),
    );
    for (const line of series) {
      const sorted = [...line.points].sort((a, b) => a.t - b.t);
      if (sorted.length > 1) {
        svg.append(s("polyline", { class: "series", points: sorted.map((p) => `${x(p.t.getTime())},${y(p.v)}`).join(" "), stroke: line.colour }));
      }
      for (const p of sorted) {
        const dot = s(
          "circle",
          { class: `dot ${p.passed ? "passed" : "failed"}`, cx: x(p.t.getTime()), cy: y(p.v), r: 4, stroke: line.colour, fill: p.passed ? line.colour : "#fff", onclick: () => (location.hash = `#/runs/${p.runId}`) },
          s("title", {}, `${line.label}: ${p.v.toFixed(3)} ${unit}\n${p.t.toLocaleString()} — ${p.passed ? "passed" : "failed"} run ${shortId(p.runId)}`),
        );
        svg.append(dot);
      }
    }
    const legend = h("div", { class: "legend" }, series.map((line) => h("span", {}, swatch(line.colour), line.label)), h("span", { class: "muted" }, "● an accepted calibration (click: its run)"));
    return h("figure", { class: "chart-box", id }, h("figcaption", {}, title), legend, svg, note ? h("p", { class: "muted small" }, note) : null);
  }

  function stageChart(stages) {
    const entries = Object.entries(stages || {}).filter(([, v]) => v && Number.isFinite(v.seconds));
    if (!entries.length) return h("p", { class: "muted" }, "No stage timings.");
    const W = 640, row = 22, L = 130, R = 70;
    const H = entries.length * row + 8;
    const longest = Math.max(...entries.map(([, v]) => v.seconds)) || 1;
    const svg = s("svg", { viewBox: `0 0 ${W} ${H}`, class: "chart stages", role: "img", "aria-label": "stage timings" });
    entries.forEach(([name, value], k) => {
      const yy = 4 + k * row;
      const width = Math.max(1, (value.seconds / longest) * (W - L - R));
      svg.append(
        s("text", { class: "tick", x: L - 8, y: yy + 14, "text-anchor": "end" }, name),
        s("rect", { class: "bar", x: L, y: yy + 3, width, height: row - 8 }),
        s("text", { class: "tick", x: L + width + 6, y: yy + 14 }, `${value.seconds.toFixed(2)} s`),
      );
    });
    const total = entries.reduce((sum, [, v]) => sum + v.seconds, 0);
    return h("figure", { class: "chart-box" }, h("figcaption", {}, `Stage timings (total ${total.toFixed(1)} s)`), svg);
  }

  // -- pages ------------------------------------------------------------------------------------

  function keyForm(message) {
    setCrumbs();
    forgetButton.hidden = true;
    const input = h("input", { id: "api-key", type: "password", autocomplete: "off", required: true, placeholder: "fck_…", size: 60 });
    const error = h("p", { class: "error", id: "key-error" }, message || "");
    const form = h(
      "form",
      {
        id: "key-form",
        onsubmit: async (event) => {
          event.preventDefault();
          sessionStorage.setItem(KEY_STORAGE, input.value.trim());
          try {
            await api("/v1/fleet?limit=1");
            route();
          } catch (err) {
            sessionStorage.removeItem(KEY_STORAGE);
            error.textContent = err.status === 403 ? "This key may not read the fleet: use a key with the read scope." : `The key was refused: ${err.message}`;
          }
        },
      },
      h("label", { for: "api-key" }, "API key"),
      input,
      h("button", { type: "submit" }, "Open the dashboard"),
    );
    show(
      h(
        "section",
        { class: "card narrow" },
        h("h1", {}, "fleetcal dashboard"),
        h("p", {}, "Enter an API key with the read scope (", h("code", {}, "fleetcal keys create --scope read --data-dir DIR"), " with the DIR the service runs on, or the admin key ", h("code", {}, "fleetcal serve"), " printed on its first start). It is kept in this browser tab's session only."),
        h("p", { class: "muted small" }, "A key that also has the override scope (", h("code", {}, "--scope read --scope override"), ") may accept a failed calibration or reject a passed one; an admin key also sees the webhooks and their deliveries."),
        form,
        error,
      ),
    );
    input.focus();
  }

  const FLEET_PAGE = 200;

  async function overviewPage(my) {
    setCrumbs();
    const [fleet, recent] = await Promise.all([api(`/v1/fleet?limit=${FLEET_PAGE}`), api("/v1/runs?limit=10")]);
    if (my !== generation) return;
    // The server counts the whole fleet; the table shows one page at a time.
    const totals = fleet.totals;
    const tiles = h(
      "div",
      { class: "tiles", id: "fleet-totals" },
      tile("Robots", totals.robots, "", "robots"),
      tile("Latest run passed", totals.latest_passed, "pass", "latest_passed"),
      tile("Latest run failed", totals.latest_failed, "fail", "latest_failed"),
      tile("In progress", totals.in_progress, "", "in_progress"),
      tile("No accepted calibration", totals.robots - totals.with_accepted, "", "without_accepted"),
    );
    const body = h("tbody", {}, fleet.items.map(fleetRow));
    let cursor = fleet.next_cursor;
    const shown = h("p", { class: "muted", id: "fleet-shown" });
    const more = h("button", { type: "button", id: "more-robots" }, "Load more robots");
    const update = () => {
      shown.textContent = `Showing ${body.children.length} of ${totals.robots} robots.`;
      more.hidden = !cursor;
    };
    more.addEventListener("click", async () => {
      more.disabled = true;
      try {
        const page = await api(`/v1/fleet${qs({ limit: FLEET_PAGE, cursor })}`);
        cursor = page.next_cursor;
        body.append(...page.items.map(fleetRow));
      } finally {
        more.disabled = false;
        update();
      }
    });
    update();
    const table = fleet.items.length
      ? h("table", { id: "fleet" }, h("thead", {}, h("tr", {}, ["Robot", "Model", "Latest run", "Verdict", "Metric error", "Uploaded", "Calibration in use"].map((t) => h("th", {}, t)))), body)
      : h("p", { class: "muted", id: "fleet-empty" }, "No robots yet. A robot appears when it uploads its first recording (POST /v1/robots/{id}/runs), e.g. with `fleetcal demo`.");
    show(
      h("h1", {}, "Fleet"),
      tiles,
      h("section", { class: "card" }, h("h2", {}, "Robots"), table, fleet.items.length ? [shown, more] : null, fleetDownload()),
      h("section", { class: "card" }, h("h2", {}, "Recent runs"), runTable(recent.items, true)),
    );
  }

  function fleetDownload() {
    const message = h("p", { class: "error", id: "fleet-download-error" });
    const button = downloadButton({ label: "Calibrations in use (CSV)", path: () => "/v1/fleet/calibrations.csv", fallback: "fleet-calibrations.csv", message, attrs: { id: "fleet-csv" } });
    return h("div", { class: "buttons fleet-download" }, button, h("span", { class: "muted small" }, "every robot's calibration in use, one row per LiDAR"), message);
  }

  function fleetRow(robot) {
    const run = robot.latest_run;
    return h(
      "tr",
      { dataset: { robotId: robot.id } },
      h("td", {}, h("a", { href: `#/robots/${encodeURIComponent(robot.id)}`, class: "robot-link" }, robot.id)),
      h("td", {}, robot.model || h("span", { class: "muted" }, "–")),
      h("td", {}, run ? [h("a", { href: `#/runs/${run.id}` }, `${run.kind.replaceAll("_", " ")} ${shortId(run.id)}`), " ", statusBadge(run.status)] : h("span", { class: "muted" }, "no run yet")),
      h("td", {}, run ? [verdictBadge(run.passed), " ", acceptedBadge(run.passed, run.accepted, false)] : "–"),
      h("td", { class: "num" }, run ? mm(run.metric_error_final) : "–"),
      h("td", {}, run ? when(run.created_at) : "–"),
      h("td", {}, robot.latest_calibration ? [h("a", { href: `#/runs/${robot.latest_calibration.run_id}` }, "accepted"), " ", when(robot.latest_calibration.measured_at)] : h("span", { class: "muted" }, "none yet")),
    );
  }

  function tile(label, value, kind, name) {
    return h("div", { class: `tile ${kind || ""}`, dataset: { total: name } }, h("div", { class: "tile-value" }, value), h("div", { class: "tile-label" }, label));
  }

  function runTable(runs, withRobot) {
    if (!runs.length) return h("p", { class: "muted" }, "No runs yet.");
    const head = ["Run", withRobot ? "Robot" : null, "Kind", "Status", "Verdict", "Metric error", "Uploaded", "Took"].filter(Boolean);
    return h(
      "table",
      { class: "runs" },
      h("thead", {}, h("tr", {}, head.map((t) => h("th", {}, t)))),
      h(
        "tbody",
        {},
        runs.map((run) =>
          h(
            "tr",
            { dataset: { runId: run.id } },
            h("td", {}, h("a", { href: `#/runs/${run.id}` }, shortId(run.id))),
            withRobot ? h("td", {}, h("a", { href: `#/robots/${encodeURIComponent(run.robot_id)}` }, run.robot_id)) : null,
            h("td", {}, run.kind.replaceAll("_", " ")),
            h("td", {}, statusBadge(run.status)),
            h("td", {}, verdictBadge(run.passed), " ", acceptedBadge(run.passed, run.accepted, false)),
            h("td", { class: "num" }, mm(run.metric_error_final)),
            h("td", {}, when(run.created_at)),
            h("td", { class: "num" }, run.started_at && run.finished_at ? `${((new Date(run.finished_at) - new Date(run.started_at)) / 1000).toFixed(1)} s` : "–"),
          ),
        ),
      ),
    );
  }

  async function allHistory(robotId) {
    const items = [];
    let cursor = null;
    do {
      const page = await api(`/v1/robots/${encodeURIComponent(robotId)}/history${qs({ limit: 10000, cursor })}`);
      items.push(...page.items);
      cursor = page.next_cursor;
    } while (cursor);
    return items;
  }

  async function robotPage(robotId, my) {
    setCrumbs([robotId, null]);
    const path = `/v1/robots/${encodeURIComponent(robotId)}`;
    const [robot, history, runs] = await Promise.all([api(path), allHistory(robotId), api(`/v1/runs${qs({ robot_id: robotId, limit: 25 })}`)]);
    let limits = {};
    if (robot.tolerance_profile) {
      try {
        limits = (await api(`/v1/tolerance-profiles/${encodeURIComponent(robot.tolerance_profile)}`)).limits || {};
      } catch {
        limits = {};
      }
    }
    if (my !== generation) return;
    const frames = [...new Set(history.map((p) => p.frame))].sort((a, b) => {
      const ra = history.find((p) => p.frame === a).is_reference, rb = history.find((p) => p.frame === b).is_reference;
      return ra === rb ? a.localeCompare(b) : ra ? -1 : 1;
    });
    const runsBody = h("div", {}, runTable(runs.items, false));
    let cursor = runs.next_cursor;
    const more = h("button", {
      type: "button",
      hidden: !cursor,
      onclick: async () => {
        const page = await api(`/v1/runs${qs({ robot_id: robotId, limit: 25, cursor })}`);
        cursor = page.next_cursor;
        more.hidden = !cursor;
        runsBody.append(runTable(page.items, false));
      },
    }, "Load older runs");
    const accepted = history.filter((p) => p.accepted ?? p.passed).at(-1);
    show(
      h("h1", {}, `Robot ${robot.id}`),
      h(
        "dl",
        { class: "facts" },
        fact("Model", robot.model || "–"),
        fact("Tolerance profile", robot.tolerance_profile || "none"),
        fact("Latest run", robot.latest_run ? [h("a", { href: `#/runs/${robot.latest_run.id}` }, shortId(robot.latest_run.id)), " ", statusBadge(robot.latest_run.status), " ", verdictBadge(robot.latest_run.passed)] : "none"),
        fact("Calibration in use", h("span", { id: "calibration-in-use", dataset: { runId: accepted ? accepted.run_id : "" } }, accepted ? [h("a", { href: `#/runs/${accepted.run_id}` }, shortId(accepted.run_id)), " ", when(accepted.measured_at)] : "none accepted yet")),
        fact("Registered", when(robot.created_at)),
      ),
      h("section", { class: "card", id: "extrinsics" }, h("h2", {}, "Extrinsics over time"), frames.length ? frames.map((frame, i) => lidarHistory(frame, i, history.filter((p) => p.frame === frame), limits)) : h("p", { class: "muted" }, "No calibrated runs yet.")),
      h("section", { class: "card" }, h("h2", {}, "Runs"), h("p", {}, h("a", { href: fleetcal.compare.href(robot.id), id: "compare-link" }, "Compare two runs")), runsBody, more),
      robotDownloads(robot.id),
    );
  }

  function robotDownloads(robotId) {
    const message = h("p", { class: "error", id: "robot-download-error" });
    const path = `/v1/robots/${encodeURIComponent(robotId)}/history.csv`;
    const csv = (label, id, query) => downloadButton({ label, path: () => `${path}${qs(query)}`, fallback: `${robotId}-history.csv`, message, attrs: { id } });
    return h(
      "section",
      { class: "card", id: "robot-downloads" },
      h("h2", {}, "Downloads"),
      h("div", { class: "buttons" }, csv("History (CSV)", "history-csv", {}), csv("Accepted calibrations only (CSV)", "accepted-csv", { accepted: "true" })),
      h("p", { class: "muted small" }, "One row per LiDAR and run, oldest first: T_base_lidar as translation (m) and quaternion, with the verdict and whether it is accepted."),
      message,
    );
  }

  function lidarHistory(frame, index, points, limits) {
    const colour = COLOURS[index % COLOURS.length];
    const drift = ofAccepted(points);
    const isReference = points.some((p) => p.is_reference);
    const heading = h("h3", {}, swatch(colour), frame, isReference ? h("span", { class: "muted" }, " (reference)") : null);
    const leftOut = drift.failed
      ? h(
          "p",
          { class: "muted small left-out" },
          `${drift.failed} failed run${drift.failed === 1 ? " is" : "s are"} left out: only accepted calibrations are compared.`,
          drift.newestFailed ? [" The newest run (", h("a", { href: `#/runs/${drift.newestFailed.run_id}` }, shortId(drift.newestFailed.run_id)), `, failed ${ago(drift.newestFailed.measured_at)}) is one of them.`] : null,
        )
      : null;
    if (!drift.latest) {
      return h("article", { class: "lidar", dataset: { frame } }, heading, h("p", { class: "drift" }, "No accepted calibration yet: no drift to show."), leftOut);
    }
    const base = drift.changes.length > 1 ? "the first accepted calibration" : "the only accepted calibration";
    const tLimit = limits.max_translation_drift_m, rLimit = limits.max_rotation_drift_deg;
    const within = (value, limit) => (limit === undefined || limit === null ? null : value <= limit);
    const tOk = within(drift.translationMm / 1000, tLimit), rOk = within(drift.rotationDeg, rLimit);
    const series = (key, labels) => labels.map((label, k) => ({ label, colour: AXIS_COLOURS[k], points: drift.changes.map((c) => ({ t: c.t, v: c[key][k], passed: true, runId: c.point.run_id })) }));
    const latest = drift.latest;
    const judged = (ok) => (ok === null ? h("span", { class: "muted" }, "no limit") : h("span", { class: `badge ${ok ? "pass" : "fail"}` }, ok ? "within tolerance" : "over tolerance"));
    return h(
      "article",
      { class: "lidar", dataset: { frame } },
      heading,
      h(
        "p",
        {},
        `Latest accepted: t = [${latest.translation.map((v) => v.toFixed(4)).join(", ")}] m, roll/pitch/yaw = [${latest.rpy_deg.map((v) => v.toFixed(3)).join(", ")}]° (T_base_lidar, ${ago(latest.measured_at)}). `,
      ),
      h(
        "p",
        { class: "drift" },
        `Drift since ${base}: `,
        h("strong", { class: "drift-translation" }, mm(drift.translationMm / 1000)),
        tLimit ? ` (limit ${mm(tLimit)}) ` : " ",
        judged(tOk),
        ", ",
        h("strong", { class: "drift-rotation" }, deg(drift.rotationDeg)),
        rLimit ? ` (limit ${deg(rLimit)}) ` : " ",
        judged(rOk),
      ),
      leftOut,
      h(
        "div",
        { class: "charts" },
        timeChart({
          id: `chart-${frame}-translation`,
          title: `${frame}: translation change since ${base} (base frame)`,
          unit: "mm",
          series: series("dt", ["Δx", "Δy", "Δz"]),
          band: tLimit ? { lo: -tLimit * 1000, hi: tLimit * 1000, label: `drift tolerance ±${mm(tLimit)}` } : null,
          note: tLimit ? null : "The tolerance profile sets no translation drift limit.",
        }),
        timeChart({
          id: `chart-${frame}-rotation`,
          title: `${frame}: rotation change since ${base} (about the LiDAR's axes)`,
          unit: "deg",
          series: series("dr", ["about x", "about y", "about z"]),
          band: rLimit ? { lo: -rLimit, hi: rLimit, label: `drift tolerance ±${deg(rLimit)}` } : null,
          note: rLimit ? null : "The tolerance profile sets no rotation drift limit.",
        }),
      ),
    );
  }

  // `answered`: the run as an accept or reject just returned it (drawn without asking again).
  async function runPage(runId, my, answered) {
    // Before the request: an error page (unknown run, no access) names what was asked for.
    setCrumbs([`run ${shortId(runId)}`, null]);
    const [run, me] = await Promise.all([answered || api(`/v1/runs/${runId}`), access()]);
    if (my !== generation) return;
    setCrumbs([run.robot_id, `#/robots/${encodeURIComponent(run.robot_id)}`], [`run ${shortId(run.id)}`, null]);
    const active = run.status === "queued" || run.status === "running";
    const doc = run.result;
    const sections = [
      h("h1", {}, `Run ${shortId(run.id)} `, statusBadge(run.status), " ", h("span", { id: "verdict" }, verdictBadge(doc ? doc.verdict.passed : null)), " ", h("span", { id: "accepted" }, doc ? acceptedBadge(doc.verdict.passed, run.accepted, true) : null)),
      h(
        "dl",
        { class: "facts" },
        fact("Robot", h("a", { href: `#/robots/${encodeURIComponent(run.robot_id)}` }, run.robot_id)),
        fact("Kind", run.kind.replaceAll("_", " ")),
        fact("Uploaded", when(run.created_at)),
        fact("Attempts", `${run.attempts} of ${run.max_attempts}`),
        fact("Recording", `${run.upload.format}, ${(run.upload.size / 1e6).toFixed(1)} MB`),
        doc ? fact("Pipeline", `${doc.pipeline_version} (${(doc.config_hash || "").slice(0, 15)}…)`) : null,
      ),
    ];
    if (active) sections.push(progressCard(run));
    if (run.error) sections.push(h("section", { class: "card error-card", id: "run-error" }, h("h2", {}, run.error.title), h("p", {}, run.error.detail)));
    if (doc) {
      sections.push(
        h(
          "section",
          { class: "card" },
          h("h2", {}, "Metric error"),
          h("p", { class: "metric", id: "metric-error" }, h("span", {}, `${mm(doc.metric_error.initial)} before`), " → ", h("strong", {}, `${mm(doc.metric_error.final)} after`), " calibration"),
          h("p", { class: "muted small" }, "Mean distance of the other LiDARs' object points to the reference LiDAR's map."),
        ),
        checksCard(doc.verdict),
        fleetcal.overrides.card(run, me, (decided) => runPage(decided.id, my, decided)),
        imagesCard(run),
        lidarsCard(doc),
        doc.drift ? driftCard(doc.drift) : null,
        h("section", { class: "card" }, h("h2", {}, "Stage timings"), stageChart(doc.stages)),
        downloadsCard(run),
      );
    }
    show(...sections.filter(Boolean));
    if (active) pollProgress(run, my);
  }

  // While a run is queued or running, only its progress card and status change: update those in
  // place each second, and draw the whole page again once the run has finished.
  function pollProgress(run, my) {
    setTimeout(async () => {
      if (my !== generation) return;
      try {
        const now = await api(`/v1/runs/${run.id}`);
        if (my !== generation) return;
        if (now.status === "queued" || now.status === "running") {
          document.getElementById("progress").replaceWith(progressCard(now));
          document.querySelector("h1 .badge[data-status]").replaceWith(statusBadge(now.status));
          pollProgress(now, my);
        } else {
          await runPage(run.id, my);
        }
      } catch (err) {
        if (my === generation) showError(err);
      }
    }, POLL_MS);
  }

  function progressCard(run) {
    const fraction = run.status === "queued" ? 0 : Math.max(0, Math.min(1, run.progress || 0));
    const bar = h("div", { class: "progress-bar" });
    bar.style.width = `${(fraction * 100).toFixed(0)}%`;
    return h(
      "section",
      { class: "card", id: "progress" },
      h("h2", {}, run.status === "queued" ? "Waiting for a worker" : `Running: ${(run.stage || "starting").replaceAll("_", " ")}`),
      h("div", { class: "progress", role: "progressbar", "aria-valuenow": Math.round(fraction * 100), "aria-valuemin": 0, "aria-valuemax": 100 }, bar),
      h("p", { class: "muted small" }, `${(fraction * 100).toFixed(0)} % — this page updates every second.`),
    );
  }

  function checksCard(verdict) {
    return h(
      "section",
      { class: "card", id: "checks" },
      h("h2", {}, "Verdict ", verdictBadge(verdict.passed)),
      h(
        "table",
        {},
        h("thead", {}, h("tr", {}, ["Check", "Value", "Limit", "", "Detail"].map((t) => h("th", {}, t)))),
        h(
          "tbody",
          {},
          (verdict.checks || []).map((check) => {
            const cells = checkCells(check);
            return h(
              "tr",
              { class: check.passed ? "" : "failed-row", dataset: { check: check.name } },
              h("td", {}, h("code", {}, check.name)),
              h("td", { class: "num check-value" }, cells.value),
              h("td", { class: "num check-limit" }, cells.limit),
              h("td", {}, h("span", { class: `badge ${check.passed ? "pass" : "fail"}` }, check.passed ? "pass" : "fail")),
              h("td", {}, check.detail || ""),
            );
          }),
        ),
      ),
    );
  }

  function imagesCard(run) {
    const holder = h("div", { class: "images" }, h("p", { class: "muted" }, "Loading the report images…"));
    (async () => {
      const my = generation;
      try {
        const index = await api(`/v1/runs/${run.id}/report`);
        if (my !== generation) return;
        if (!index.images.length) {
          const why = run.result && run.result.report && run.result.report.error;
          holder.replaceChildren(h("p", { class: "muted", id: "no-images" }, why ? `No report images: ${why}` : "No report images for this run."));
          return;
        }
        holder.replaceChildren(
          ...index.images.map((image) => {
            const img = h("img", { class: "report-image", alt: image.title, dataset: { name: image.name } });
            const link = h("a", { target: "_blank", rel: "noopener" }, img);
            blobUrl(image.url).then((url) => {
              img.addEventListener("load", () => (img.dataset.loaded = "true"), { once: true });
              img.src = url;
              link.href = url;
            });
            return h("figure", { class: `report report-${image.name}` }, h("figcaption", {}, image.title), link);
          }),
        );
      } catch (err) {
        holder.replaceChildren(h("p", { class: "error" }, `Cannot load the report images: ${err.message}`));
      }
    })();
    return h("section", { class: "card", id: "report" }, h("h2", {}, "Before and after"), holder);
  }

  function lidarsCard(doc) {
    const frames = Object.keys(doc.lidars).sort((a, b) => (a === doc.reference_frame ? -1 : b === doc.reference_frame ? 1 : a.localeCompare(b)));
    const pose = (p) => (p ? `[${p.translation.map((v) => v.toFixed(4)).join(", ")}] m, [${p.rpy_deg.map((v) => v.toFixed(3)).join(", ")}]°` : "–");
    return h(
      "section",
      { class: "card", id: "lidars" },
      h("h2", {}, `Extrinsics T_${doc.base_frame || "base"}_lidar (translation, roll/pitch/yaw)`),
      h(
        "table",
        {},
        h("thead", {}, h("tr", {}, ["LiDAR", "Initial", "Calibrated", "Change", "Std. dev. (1σ)"].map((t) => h("th", {}, t)))),
        h(
          "tbody",
          {},
          frames.map((frame, i) => {
            const lidar = doc.lidars[frame];
            const cal = lidar.calibrated, init = lidar.initial;
            const change = cal && init ? [Math.hypot(...cal.translation.map((v, k) => v - init.translation[k])), Math.hypot(...rotationChangeDeg(init.rotation_xyzw, cal.rotation_xyzw))] : null;
            const sd = stddevSummary(lidar, frame === doc.reference_frame);
            return h(
              "tr",
              { dataset: { frame } },
              h("td", {}, swatch(COLOURS[i % COLOURS.length]), frame, frame === doc.reference_frame ? h("span", { class: "muted" }, " (reference)") : null),
              h("td", { class: "mono" }, pose(init)),
              h("td", { class: "mono" }, cal ? pose(cal) : h("span", { class: "badge fail" }, (lidar.undetermined || []).length ? `not calibrated: ${lidar.undetermined.join(", ")} undetermined` : "not calibrated")),
              h("td", { class: "num" }, change ? `${mm(change[0])}, ${deg(change[1])}` : "–"),
              h(
                "td",
                { class: "num stddev" },
                sd.undetermined.length ? [h("span", { class: "badge fail undetermined" }, `undetermined: ${sd.undetermined.join(", ")}`), sd.text ? h("div", { class: "muted small" }, `others ${sd.text}`) : null] : sd.text || "–",
              ),
            );
          }),
        ),
      ),
    );
  }

  function driftCard(drift) {
    const against = drift.against === "design" ? "the model's design extrinsics" : "the last accepted calibration";
    return h(
      "section",
      { class: "card", id: "drift" },
      h("h2", {}, `Compared with ${against}`),
      drift.run_id ? h("p", {}, "Reference run: ", h("a", { href: `#/runs/${drift.run_id}` }, shortId(drift.run_id))) : null,
      h(
        "table",
        {},
        h("thead", {}, h("tr", {}, ["LiDAR", "Translation", "Rotation"].map((t) => h("th", {}, t)))),
        h("tbody", {}, Object.entries(drift.lidars || {}).map(([frame, d]) => h("tr", {}, h("td", {}, frame), h("td", { class: "num" }, mm(d.translation_m)), h("td", { class: "num" }, deg(d.rotation_deg))))),
      ),
      (drift.missing || []).length ? h("p", { class: "error" }, `Not calibrated in this run: ${drift.missing.join(", ")}`) : null,
    );
  }

  function downloadsCard(run) {
    const doc = run.result;
    const message = h("p", { class: "error", id: "download-error" });
    const allow = h("input", { type: "checkbox", id: "allow-failed" });
    const button = (label, format, fallback) =>
      downloadButton({
        label,
        path: () => `/v1/runs/${run.id}/exports/${format}${qs({ allow_failed: allow.checked ? "true" : null })}`,
        fallback,
        message,
        attrs: { class: "download", dataset: { format } },
      });
    const resultJson = h(
      "button",
      {
        type: "button",
        class: "download",
        dataset: { format: "result" },
        onclick: () => saveBlob(new Blob([JSON.stringify(doc, null, 2)], { type: "application/json" }), `${run.robot_id}-${shortId(run.id)}-result.json`),
      },
      "result.json",
    );
    return h(
      "section",
      { class: "card", id: "downloads" },
      h("h2", {}, "Downloads"),
      h(
        "div",
        { class: "buttons" },
        resultJson,
        button("tf_static launch (ROS 2)", "tf-static", "tf_static.launch.yaml"),
        button("URDF snippet", "urdf", "lidars.urdf"),
        button("extrinsics.yaml", "extrinsics", "extrinsics.yaml"),
        button("Autoware sensor_kit_calibration.yaml", "autoware", "sensor_kit_calibration.yaml"),
        button("Calibrated recording", "recording", "calibrated.mcap"),
      ),
      doc.verdict.passed ? null : h("p", {}, h("label", {}, allow, " Export anyway: this calibration failed its verdict.")),
      message,
    );
  }

  function showError(err) {
    if (err instanceof ApiError && err.status === 401) return keyForm("The key is unknown or revoked; enter another.");
    show(h("section", { class: "card error-card", id: "page-error" }, h("h1", {}, err.problem ? err.problem.title : "Something went wrong"), h("p", {}, err.message), h("p", {}, h("a", { href: "#/" }, "Back to the fleet"))));
  }

  // -- routing ----------------------------------------------------------------------------------

  async function route() {
    const my = ++generation;
    for (const url of blobUrls) URL.revokeObjectURL(url);
    blobUrls = [];
    if (!sessionStorage.getItem(KEY_STORAGE)) {
      keyForm();
      app.dataset.route = "key";
      app.dataset.ready = "true";
      return;
    }
    forgetButton.hidden = false;
    const header = access()
      .then((me) => {
        navWebhooks.hidden = !me.may("admin");
        keyName.textContent = me.name ? `key: ${me.name}` : "";
      })
      .catch(() => (navWebhooks.hidden = true)); // the page itself says why the key is refused
    const path = location.hash.replace(/^#/, "") || "/";
    // For tests and scripts: which page is shown, and whether it has finished drawing.
    app.dataset.route = path;
    app.dataset.ready = "false";
    const [page, query] = path.split("?");
    const params = new URLSearchParams(query || "");
    // Pages of the other scripts return their content; it is shown if still wanted.
    const draw = async (nodes) => {
      const content = await nodes;
      if (my === generation) show(...content);
    };
    let match;
    try {
      if ((match = path.match(/^\/robots\/([^/]+)$/))) await robotPage(decodeURIComponent(match[1]), my);
      else if ((match = page.match(/^\/robots\/([^/]+)\/compare$/))) {
        const robotId = decodeURIComponent(match[1]);
        setCrumbs([robotId, `#/robots/${encodeURIComponent(robotId)}`], ["compare", null]);
        await draw(fleetcal.compare.page(robotId, params));
      } else if ((match = path.match(/^\/runs\/([0-9a-f-]{36})$/))) await runPage(match[1], my);
      else if (path === "/webhooks") {
        setCrumbs(["webhooks", null]);
        await draw(fleetcal.webhooks.listPage());
      } else if ((match = page.match(/^\/webhooks\/([0-9a-f-]{36})$/))) {
        setCrumbs(["webhooks", "#/webhooks"], [`webhook ${shortId(match[1])}`, null]);
        await draw(fleetcal.webhooks.deliveriesPage(match[1], params));
      } else if (path === "/") await overviewPage(my);
      else {
        setCrumbs([path, null]);
        throw new ApiError(404, {
          title: "No such page",
          detail: `The dashboard has no page ${path}: pages are the fleet (#/), a robot (#/robots/ID), two of its runs compared (#/robots/ID/compare), a run (#/runs/UUID) and, for admin keys, the webhooks (#/webhooks).`,
        });
      }
    } catch (err) {
      if (my === generation) showError(err);
    }
    await header;
    if (my === generation) app.dataset.ready = "true";
  }

  forgetButton.addEventListener("click", () => {
    sessionStorage.removeItem(KEY_STORAGE);
    route();
  });
  window.addEventListener("hashchange", route);
  route();
})();

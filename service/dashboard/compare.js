// fleetcal dashboard: two runs of a robot side by side (`#/robots/<id>/compare?from=&to=`), per
// LiDAR how far its mount moved and turned between them, with both verdicts: what a maintenance
// engineer asks after a mount was touched. The API computes the change (`/compare`); this page
// only picks the runs and shows it. On `fleetcal.compare`.
"use strict";

(() => {
  const { api, qs } = fleetcal.api;
  const { h, fact, when, shortId, verdictBadge, acceptedBadge } = fleetcal.ui;
  const { mm, deg } = fleetcal.format;
  const RUNS = 100;

  function href(robotId, from, to) {
    return `#/robots/${encodeURIComponent(robotId)}/compare${qs({ from, to })}`;
  }

  function runLabel(run) {
    const verdict = run.passed ? "passed" : "failed";
    const overridden = run.accepted !== null && run.accepted !== run.passed ? (run.accepted ? ", accepted by an operator" : ", rejected by an operator") : "";
    return `${shortId(run.id)} — ${run.kind.replaceAll("_", " ")}, ${new Date(run.created_at).toLocaleString()}, ${verdict}${overridden}`;
  }

  function picker(robotId, runs, from, to) {
    // A run named in the address but not among the listed ones (older, or another robot's) is
    // still the one compared: it gets its own option.
    const select = (id, chosen) =>
      h(
        "select",
        { id, required: true },
        runs.some((run) => run.id === chosen) ? null : h("option", { value: chosen, selected: true }, `${shortId(chosen)} — from the address`),
        runs.map((run) => h("option", { value: run.id, selected: run.id === chosen }, runLabel(run))),
      );
    const first = select("compare-from", from), second = select("compare-to", to);
    return h(
      "form",
      {
        id: "compare-form",
        onsubmit: (event) => {
          event.preventDefault();
          location.hash = href(robotId, first.value, second.value);
        },
      },
      h("label", { for: "compare-from" }, "From"),
      first,
      h("label", { for: "compare-to" }, "to"),
      second,
      h("button", { type: "submit" }, "Compare"),
    );
  }

  function side(label, compared) {
    return fact(label, [h("a", { href: `#/runs/${compared.run_id}` }, shortId(compared.run_id)), " ", when(compared.measured_at), " ", verdictBadge(compared.passed), " ", acceptedBadge(compared.passed, compared.accepted, false)]);
  }

  function signedMm(metres) {
    return metres > 0 ? `+${mm(metres)}` : mm(metres);
  }

  function changeRow(frame, change, comparison) {
    if (change.translation_m === null || change.rotation_deg === null) {
      const missing = [change.in_from ? null : `run ${shortId(comparison.from_run.run_id)}`, change.in_to ? null : `run ${shortId(comparison.to_run.run_id)}`].filter(Boolean);
      return h("tr", { dataset: { frame }, class: "failed-row" }, h("td", {}, frame), h("td", { colspan: 5, class: "not-compared" }, `Not compared: ${missing.join(" and ")} did not calibrate it.`));
    }
    return h(
      "tr",
      { dataset: { frame } },
      h("td", {}, frame),
      h("td", { class: "num translation" }, mm(change.translation_m)),
      change.delta_translation.map((v, k) => h("td", { class: `num delta delta-${"xyz"[k]}` }, signedMm(v))),
      h("td", { class: "num rotation" }, deg(change.rotation_deg)),
    );
  }

  function comparisonCard(comparison) {
    const frames = Object.keys(comparison.lidars).sort();
    return h(
      "section",
      { class: "card", id: "comparison" },
      h("h2", {}, "Change of each LiDAR's T_base_lidar"),
      h("dl", { class: "facts" }, side("From", comparison.from_run), side("To", comparison.to_run)),
      h(
        "table",
        {},
        h("thead", {}, h("tr", {}, ["LiDAR", "Translation", "Δx", "Δy", "Δz", "Rotation"].map((t) => h("th", {}, t)))),
        h("tbody", {}, frames.map((frame) => changeRow(frame, comparison.lidars[frame], comparison))),
      ),
      h("p", { class: "muted small" }, "Translation: the distance the LiDAR moved, and Δx, Δy, Δz its change along the base frame's axes (to minus from). Rotation: the angle of the rotation from its first mount to its second."),
    );
  }

  // The page's content: the picker and, for two chosen runs (by default the two newest with a
  // result), their comparison or the API's reason for refusing it.
  async function page(robotId, params) {
    const runs = (await api(`/v1/runs${qs({ robot_id: robotId, status: "succeeded", limit: RUNS })}`)).items;
    const heading = h("h1", {}, `Compare runs of robot ${robotId}`);
    if (runs.length < 2) {
      return [heading, h("section", { class: "card", id: "compare-none" }, h("p", {}, `Comparing needs two runs with a result; robot ${robotId} has ${runs.length}.`), h("p", {}, h("a", { href: `#/robots/${encodeURIComponent(robotId)}` }, "Back to the robot")))];
    }
    const from = params.get("from") || runs[1].id;
    const to = params.get("to") || runs[0].id;
    const form = h("section", { class: "card" }, picker(robotId, runs, from, to), runs.length === RUNS ? h("p", { class: "muted small" }, `The ${RUNS} newest runs with a result.`) : null);
    try {
      const comparison = await api(`/v1/robots/${encodeURIComponent(robotId)}/compare${qs({ from, to })}`);
      return [heading, form, comparisonCard(comparison)];
    } catch (err) {
      if (err.status === 401) throw err;
      return [heading, form, h("section", { class: "card error-card", id: "compare-error" }, h("h2", {}, err.problem ? err.problem.title : "Cannot compare"), h("p", {}, err.message))];
    }
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, { compare: { page, href } });
})();

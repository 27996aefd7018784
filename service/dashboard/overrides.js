// fleetcal dashboard: an operator's accept / reject of a run's calibration, on its run page. A
// failed calibration can be accepted and a passed one rejected, always with a reason that the
// audit trail keeps beside the key that gave it. Only a key with the override scope gets the
// form; any other is told which key it needs. On `fleetcal.overrides`.
"use strict";

(() => {
  const { post } = fleetcal.api;
  const { h, when } = fleetcal.ui;

  function state(run) {
    const passed = run.result.verdict.passed;
    if (run.accepted && passed) return "It passed its verdict and is accepted: the robot may use it (the newest accepted calibration is the one in use).";
    if (run.accepted) return "An operator accepted it despite its failed verdict: the robot may use it (the newest accepted calibration is the one in use).";
    if (passed) return "An operator rejected it although it passed its verdict: the robot keeps its previous accepted calibration.";
    return "It failed its verdict and is not accepted: the robot keeps its previous accepted calibration.";
  }

  function trail(overrides) {
    if (!overrides.length) return h("p", { class: "muted small", id: "override-trail-empty" }, "No operator has accepted or rejected it.");
    return h(
      "table",
      { id: "override-trail" },
      h("thead", {}, h("tr", {}, ["When", "Decision", "By", "Reason"].map((t) => h("th", {}, t)))),
      h(
        "tbody",
        {},
        overrides.map((o) =>
          h(
            "tr",
            { dataset: { action: o.action } },
            h("td", {}, when(o.created_at)),
            h("td", {}, h("span", { class: `badge ${o.action === "accept" ? "pass" : "fail"}` }, o.action === "accept" ? "accepted" : "rejected")),
            h("td", {}, o.key_name || h("code", {}, o.key_id)),
            h("td", { class: "reason" }, o.reason),
          ),
        ),
      ),
    );
  }

  // `onDone(run)`: called with the run as the API answers after the decision.
  function form(run, onDone) {
    const action = run.accepted ? "reject" : "accept";
    const label = run.accepted ? "Reject this calibration" : "Accept this calibration";
    const reason = h("textarea", { id: "override-reason", rows: 2, maxlength: 1000, required: true, placeholder: "e.g. mount checked by hand; the metric error came from a person walking by" });
    const error = h("p", { class: "error", id: "override-error", role: "alert" });
    const button = h("button", { type: "submit", id: `${action}-run`, class: action }, label);
    return h(
      "form",
      {
        id: "override-form",
        class: "override-form",
        novalidate: true, // the missing reason is said in the page, not in a browser bubble
        onsubmit: async (event) => {
          event.preventDefault();
          error.textContent = "";
          const why = reason.value.trim();
          if (!why) {
            error.textContent = "Give a reason: it is kept in the audit trail with the name of your key.";
            reason.focus();
            return;
          }
          button.disabled = true;
          try {
            onDone(await post(`/v1/runs/${run.id}/${action}`, { reason: why }));
          } catch (err) {
            const title = err.problem && err.problem.title ? `${err.problem.title}: ` : "";
            error.textContent = `The service refused to ${action} it. ${title}${err.message}`;
            button.disabled = false;
          }
        },
      },
      h("label", { for: "override-reason" }, "Reason"),
      reason,
      button,
      error,
    );
  }

  // The card; `me`: what the key may do (`fleetcal.api.access`).
  function card(run, me, onDone) {
    const decide = me.may("override")
      ? form(run, onDone)
      : h(
          "p",
          { class: "muted", id: "override-refused" },
          "This key may not accept or reject calibrations: that needs a key with the override scope (",
          h("code", {}, "fleetcal keys create --scope read --scope override"),
          ").",
        );
    return h("section", { class: "card", id: "override" }, h("h2", {}, "Operator decision"), h("p", { id: "override-state" }, state(run)), trail(run.overrides || []), decide);
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, { overrides: { card } });
})();

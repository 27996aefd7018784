// fleetcal dashboard: building the page (elements, badges, times, download buttons), shared by
// every page's script. On `fleetcal.ui`; needs `fleetcal.api` (api.js, loaded first).
"use strict";

(() => {
  const app = document.getElementById("app");
  const crumbs = document.getElementById("crumbs");

  // -- elements ---------------------------------------------------------------------------------

  function h(tag, attrs, ...children) {
    const node = document.createElement(tag);
    setAttributes(node, attrs);
    node.append(...children.flat().filter((c) => c !== null && c !== undefined && c !== false).map(asNode));
    return node;
  }

  const SVG_NS = "http://www.w3.org/2000/svg";
  function s(tag, attrs, ...children) {
    const node = document.createElementNS(SVG_NS, tag);
    setAttributes(node, attrs);
    node.append(...children.flat().filter((c) => c !== null && c !== undefined && c !== false).map(asNode));
    return node;
  }

  function setAttributes(node, attrs) {
    for (const [name, value] of Object.entries(attrs || {})) {
      if (value === null || value === undefined || value === false) continue;
      if (name.startsWith("on")) node.addEventListener(name.slice(2), value);
      else if (name === "dataset") Object.assign(node.dataset, value);
      else node.setAttribute(name, value === true ? "" : String(value));
    }
  }

  function asNode(child) {
    return child instanceof Node ? child : document.createTextNode(String(child));
  }

  function show(...nodes) {
    app.replaceChildren(...nodes);
  }

  function setCrumbs(...items) {
    const parts = [h("a", { href: "#/" }, "Fleet")];
    for (const [label, href] of items) parts.push(" / ", href ? h("a", { href }, label) : h("span", {}, label));
    crumbs.replaceChildren(...parts);
  }

  function fact(label, value) {
    return h("div", {}, h("dt", {}, label), h("dd", {}, value));
  }

  // -- times, ids and badges --------------------------------------------------------------------

  function ago(iso) {
    if (!iso) return "–";
    const seconds = (Date.now() - new Date(iso).getTime()) / 1000;
    const steps = [
      [60, "s", 1],
      [3600, "min", 60],
      [86400, "h", 3600],
      [86400 * 60, "d", 86400],
    ];
    for (const [limit, unit, size] of steps) if (seconds < limit) return `${Math.max(0, Math.floor(seconds / size))} ${unit} ago`;
    return new Date(iso).toLocaleDateString();
  }

  function when(iso) {
    return iso ? h("time", { datetime: iso, title: new Date(iso).toLocaleString() }, ago(iso)) : "–";
  }

  function shortId(id) {
    return id.slice(0, 8);
  }

  function statusBadge(status) {
    return h("span", { class: `badge status-${status}`, dataset: { status } }, status);
  }

  function verdictBadge(passed) {
    if (passed === null || passed === undefined) return h("span", { class: "badge verdict-none" }, "no verdict");
    return h("span", { class: `badge ${passed ? "pass" : "fail"}`, dataset: { verdict: passed ? "passed" : "failed" } }, passed ? "PASSED" : "FAILED");
  }

  // Whether the calibration may be used: its verdict, unless an operator accepted or rejected it.
  // `always`: also when it simply follows the verdict (a run's own page); lists show overrides only.
  function acceptedBadge(passed, accepted, always) {
    if (accepted === null || accepted === undefined) return null;
    const overridden = accepted !== passed;
    if (!overridden && !always) return null;
    const text = overridden ? (accepted ? "accepted by an operator" : "rejected by an operator") : accepted ? "accepted" : "not accepted";
    return h("span", { class: `badge ${accepted ? "pass" : "fail"} accepted-badge`, dataset: { accepted: String(accepted), overridden: String(overridden) } }, text);
  }

  function swatch(colour) {
    const node = h("span", { class: "swatch" });
    node.style.background = colour;
    return node;
  }

  // -- downloads --------------------------------------------------------------------------------

  // A button that downloads `path()` with the key in a header; failures go to `message`.
  function downloadButton({ label, path, fallback, message, attrs }) {
    return h(
      "button",
      {
        type: "button",
        ...attrs,
        onclick: async (event) => {
          const target = event.currentTarget;
          message.textContent = "";
          target.disabled = true;
          try {
            target.dataset.saved = await fleetcal.api.download(path(), fallback);
          } catch (err) {
            message.textContent = `${label}: ${err.message}`;
          } finally {
            target.disabled = false;
          }
        },
      },
      label,
    );
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, {
    ui: { h, s, show, setCrumbs, fact, ago, when, shortId, statusBadge, verdictBadge, acceptedBadge, swatch, downloadButton },
  });
})();

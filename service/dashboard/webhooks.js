// fleetcal dashboard, for admin keys: the registered webhooks (`#/webhooks`) and each one's
// deliveries with their outcome (`#/webhooks/<id>?status=`): whether the receiver got the event,
// after how many tries, and what went wrong last. On `fleetcal.webhooks`.
"use strict";

(() => {
  const { api, qs } = fleetcal.api;
  const { h, fact, when, shortId } = fleetcal.ui;
  const PAGE = 50;
  const STATUSES = ["pending", "delivered", "failed"];

  async function listPage() {
    const hooks = (await api("/v1/webhooks")).items;
    const table = hooks.length
      ? h(
          "table",
          { id: "webhooks" },
          h("thead", {}, h("tr", {}, ["Receiver", "Events", "Robot model", "Registered", ""].map((t) => h("th", {}, t)))),
          h(
            "tbody",
            {},
            hooks.map((hook) =>
              h(
                "tr",
                { dataset: { webhookId: hook.id } },
                h("td", { class: "mono" }, hook.url),
                h("td", {}, hook.events.join(", ")),
                h("td", {}, hook.robot_model || h("span", { class: "muted" }, "every robot")),
                h("td", {}, when(hook.created_at)),
                h("td", {}, h("a", { href: `#/webhooks/${hook.id}`, class: "deliveries-link" }, "Deliveries")),
              ),
            ),
          ),
        )
      : h("p", { class: "muted", id: "webhooks-empty" }, "No webhooks. An admin registers one with POST /v1/webhooks (see /docs).");
    return [h("h1", {}, "Webhooks"), h("section", { class: "card" }, table)];
  }

  function deliveryRow(d) {
    const next = d.status === "pending" ? ["next try ", h("time", { datetime: d.available_at }, new Date(d.available_at).toLocaleString())] : null;
    return h(
      "tr",
      { class: d.status === "failed" ? "failed-row" : "", dataset: { deliveryId: d.id, status: d.status } },
      h("td", {}, h("code", {}, d.event), h("div", { class: "muted small mono", title: "X-Fleetcal-Event-Id" }, d.event_id)),
      h("td", {}, h("a", { href: `#/robots/${encodeURIComponent(d.robot_id)}` }, d.robot_id), d.run_id ? [" ", h("a", { href: `#/runs/${d.run_id}` }, `run ${shortId(d.run_id)}`)] : null),
      h("td", {}, h("span", { class: `badge delivery-${d.status}` }, d.status)),
      h("td", { class: "num attempts" }, `${d.attempts} of ${d.max_attempts}`),
      h("td", { class: "num last-status" }, d.last_status_code === null ? "–" : String(d.last_status_code)),
      h("td", { class: "last-error" }, d.last_error || h("span", { class: "muted" }, "–")),
      h("td", {}, when(d.created_at)),
      h("td", {}, d.delivered_at ? when(d.delivered_at) : next || "–"),
    );
  }

  async function deliveriesPage(webhookId, params) {
    const status = STATUSES.includes(params.get("status")) ? params.get("status") : null;
    const path = `/v1/webhooks/${webhookId}/deliveries`;
    const [hook, first] = await Promise.all([api(`/v1/webhooks/${webhookId}`), api(`${path}${qs({ status, limit: PAGE })}`)]);
    const filter = h(
      "select",
      {
        id: "delivery-status",
        onchange: (event) => (location.hash = `#/webhooks/${webhookId}${qs({ status: event.target.value || null })}`),
      },
      h("option", { value: "", selected: !status }, "every status"),
      STATUSES.map((s) => h("option", { value: s, selected: s === status }, s)),
    );
    const body = h("tbody", {}, first.items.map(deliveryRow));
    let cursor = first.next_cursor;
    const more = h("button", { type: "button", id: "more-deliveries", hidden: !cursor }, "Load older deliveries");
    more.addEventListener("click", async () => {
      more.disabled = true;
      try {
        const page = await api(`${path}${qs({ status, limit: PAGE, cursor })}`);
        cursor = page.next_cursor;
        body.append(...page.items.map(deliveryRow));
      } finally {
        more.disabled = false;
        more.hidden = !cursor;
      }
    });
    const table = first.items.length
      ? h("table", { id: "deliveries" }, h("thead", {}, h("tr", {}, ["Event", "Robot / run", "Status", "Attempts", "Last answer", "Last error", "Created", "Delivered"].map((t) => h("th", {}, t)))), body)
      : h("p", { class: "muted", id: "deliveries-empty" }, status ? `No ${status} deliveries.` : "No deliveries yet: events this webhook subscribes to have not happened since it was registered.");
    return [
      h("h1", {}, "Webhook deliveries"),
      h("dl", { class: "facts" }, fact("Receiver", h("code", {}, hook.url)), fact("Events", hook.events.join(", ")), fact("Robot model", hook.robot_model || "every robot"), fact("Registered", when(hook.created_at))),
      h("section", { class: "card" }, h("p", {}, h("label", { for: "delivery-status" }, "Show "), filter), table, more),
    ];
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, { webhooks: { listPage, deliveriesPage } });
})();

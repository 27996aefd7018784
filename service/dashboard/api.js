// fleetcal dashboard: the /v1 API as the pages call it, on `fleetcal.api`. The key lives in this
// tab's session storage and travels in the X-API-Key header of every call, downloads included
// (fetched, then saved from a Blob): never in a URL, where logs and the history would keep it.
"use strict";

(() => {
  const KEY_STORAGE = "fleetcal.apiKey";

  class ApiError extends Error {
    constructor(status, problem) {
      super(problem.detail || problem.title || `HTTP ${status}`);
      this.status = status;
      this.problem = problem;
    }
  }

  // `json`: a body to send as JSON (POST).
  async function request(path, { method = "GET", json } = {}) {
    const key = sessionStorage.getItem(KEY_STORAGE);
    const headers = { "X-API-Key": key || "" };
    const init = { method, headers };
    if (json !== undefined) {
      headers["Content-Type"] = "application/json";
      init.body = JSON.stringify(json);
    }
    const response = await fetch(path, init);
    if (!response.ok) {
      let problem;
      try {
        problem = await response.json();
      } catch {
        problem = { title: response.statusText, detail: "" };
      }
      if (response.status === 401) sessionStorage.removeItem(KEY_STORAGE);
      throw new ApiError(response.status, problem);
    }
    return response;
  }

  async function api(path) {
    return (await request(path)).json();
  }

  async function post(path, json) {
    return (await request(path, { method: "POST", json })).json();
  }

  // Saves the response as a file named as the server's Content-Disposition says; the name saved.
  async function download(path, fallbackName) {
    const response = await request(path);
    const disposition = response.headers.get("Content-Disposition") || "";
    const match = disposition.match(/filename="?([^";]+)"?/);
    const name = match ? match[1] : fallbackName;
    saveBlob(await response.blob(), name);
    return name;
  }

  function saveBlob(blob, name) {
    const url = URL.createObjectURL(blob);
    const link = document.createElement("a");
    link.href = url;
    link.download = name;
    link.hidden = true;
    document.body.append(link);
    link.click();
    link.remove();
    setTimeout(() => URL.revokeObjectURL(url), 60_000);
  }

  function qs(params) {
    const query = new URLSearchParams();
    for (const [k, v] of Object.entries(params)) if (v !== null && v !== undefined) query.set(k, v);
    const text = query.toString();
    return text ? `?${text}` : "";
  }

  // What the key may do (`GET /v1/keys/me`), asked once per key and page load: pages offer only
  // the actions it may take. {name, may(scope)}; `admin` implies every scope.
  let known = null;
  function access() {
    const key = sessionStorage.getItem(KEY_STORAGE);
    if (!known || known.key !== key) {
      const asked = api("/v1/keys/me").then((me) => ({
        name: me.name,
        may: (scope) => me.scopes.includes("admin") || me.scopes.includes(scope),
      }));
      known = { key, asked };
      asked.catch(() => {
        if (known && known.asked === asked) known = null; // ask again next time
      });
    }
    return known.asked;
  }

  globalThis.fleetcal = Object.assign(globalThis.fleetcal || {}, {
    api: { KEY_STORAGE, ApiError, request, api, post, download, saveBlob, qs, access },
  });
})();

// zonecast operator page: reads the REST API with the token the operator entered and plots
// each zone with plotly.js (served by the service from the plotly Python package).
// No data is written into the page as HTML: text goes through textContent only.
"use strict";

(function () {
  const KEY = "zonecast-token";
  const API = "/api/v1";
  const REFRESH_MS = 60000;
  const $ = (id) => document.getElementById(id);
  let timer = null;

  class ApiError extends Error {
    constructor(status, detail) {
      super(detail);
      this.status = status;
    }
  }

  async function api(path) {
    const token = sessionStorage.getItem(KEY) || "";
    const r = await fetch(API + path, {
      headers: { Authorization: "Bearer " + token, Accept: "application/json" },
      cache: "no-store",
    });
    let body = null;
    try {
      body = await r.json();
    } catch (e) {
      body = null;
    }
    if (!r.ok) {
      throw new ApiError(r.status, (body && body.detail) || r.statusText || "request failed");
    }
    return body;
  }

  // --- small DOM helpers (text only) -------------------------------------------------
  function el(tag, text, cls) {
    const e = document.createElement(tag);
    if (text !== undefined && text !== null) e.textContent = String(text);
    if (cls) e.className = cls;
    return e;
  }

  function row(dl, term, value, cls) {
    dl.appendChild(el("dt", term));
    dl.appendChild(el("dd", value, cls));
  }

  function table(head, rows) {
    const t = el("table");
    const tr = el("tr");
    head.forEach((h) => tr.appendChild(el("th", h)));
    t.appendChild(tr);
    rows.forEach((r) => {
      const line = el("tr");
      r.forEach((c) => line.appendChild(el("td", c)));
      t.appendChild(line);
    });
    return t;
  }

  const num = (x, digits) => (x === null || x === undefined ? "—" : Number(x).toFixed(digits));

  // ISO time (UTC) -> wall-clock text in the building's time zone; plotly.js ignores time
  // zones in date strings, so the axis gets local wall-clock times
  function localTime(tz) {
    const f = new Intl.DateTimeFormat("en-GB", {
      timeZone: tz, year: "numeric", month: "2-digit", day: "2-digit",
      hour: "2-digit", minute: "2-digit", second: "2-digit", hourCycle: "h23",
    });
    return (iso) => {
      if (!iso) return null;
      const p = {};
      f.formatToParts(new Date(iso)).forEach((x) => { p[x.type] = x.value; });
      return `${p.year}-${p.month}-${p.day} ${p.hour}:${p.minute}:${p.second}`;
    };
  }

  // --- states of the page ------------------------------------------------------------
  function showError(text) {
    const e = $("error");
    e.textContent = text;
    e.hidden = false;
  }

  function clearError() {
    $("error").hidden = true;
    $("error").textContent = "";
  }

  function loggedOut(message) {
    sessionStorage.removeItem(KEY);
    if (timer !== null) clearInterval(timer);
    timer = null;
    $("content").hidden = true;
    $("zones").replaceChildren();
    $("health").replaceChildren();
    $("diagnosis").replaceChildren();
    $("building").replaceChildren();
    $("building-label").hidden = true;
    $("logout").hidden = true;
    $("updated").textContent = "";
    $("login").hidden = false;
    if (message) showError(message);
    document.body.dataset.state = message ? "error" : "login";
  }

  async function start() {
    clearError();
    document.body.dataset.state = "loading";
    let buildings;
    try {
      buildings = await api("/buildings");
    } catch (e) {
      if (e instanceof ApiError && e.status === 401) {
        loggedOut(`The token was refused (401): ${e.message}`);
      } else {
        loggedOut(`The service did not answer: ${e.message}`);
      }
      return;
    }
    $("login").hidden = true;
    $("logout").hidden = false;
    const select = $("building");
    select.replaceChildren();
    buildings.forEach((b) => select.appendChild(el("option", b.id)));
    $("building-label").hidden = buildings.length < 2;
    if (!buildings.length) {
      showError("The service serves no building (settings 'buildings').");
      document.body.dataset.state = "error";
      return;
    }
    await refresh();
    if (timer === null) timer = setInterval(refresh, REFRESH_MS);
  }

  async function refresh() {
    const id = $("building").value;
    if (!id) return;
    try {
      await show(id);
      clearError();
      document.body.dataset.state = "ready";
    } catch (e) {
      if (e instanceof ApiError && e.status === 401) {
        loggedOut(`The token was refused (401): ${e.message}`);
      } else {
        showError(`Could not show building ${id}: ${e.message}`);
        document.body.dataset.state = "error";
      }
    }
  }

  // --- one building ------------------------------------------------------------------
  async function show(id) {
    const b = "/buildings/" + encodeURIComponent(id);
    const [detail, history, health, gains, diagnosis, forecast] = await Promise.all([
      api(b), api(b + "/history?hours=48"), api(b + "/health?hours=48"),
      api(b + "/internal-gains"), api(b + "/diagnosis"),
      // 409: no forecast to serve (filter not started, an input never seen): say why
      api(b + "/forecast?horizon=24h").catch((e) => {
        if (e instanceof ApiError && e.status === 409) return { problem: e.message };
        throw e;
      }),
    ]);
    const fmt = localTime(detail.timezone);
    $("updated").textContent = `last step ${fmt(health.last_update) || "—"} (${detail.timezone})`;
    showHealth(health, fmt);
    showDiagnosis(diagnosis, fmt);
    const zones = $("zones");
    zones.replaceChildren();
    detail.zones.forEach((zone, i) => {
      zones.appendChild(zoneCard(zone, i, {
        history, health, gains, diagnosis, forecast, fmt,
      }));
    });
    $("content").hidden = false;
    // plot after the cards are in the document (plotly measures its container)
    detail.zones.forEach((zone, i) => plotZone(zone, i, history, gains, forecast, fmt));
  }

  function showHealth(h, fmt) {
    const dl = $("health");
    dl.replaceChildren();
    row(dl, "Last reading", fmt(h.last_reading) || "none");
    row(dl, "Last processed step", fmt(h.last_update) || "none");
    row(dl, "Window", h.window_steps
      ? `${fmt(h.window_start)} – ${fmt(h.window_end)} (${h.window_steps} steps)` : "no data");
    row(dl, "NIS per observed output", num(h.nis_per_dof, 2) + " (≈ 1 for a consistent filter)");
    row(dl, "Quality flags", h.quality.length ? h.quality.join(", ") : "none",
        h.quality.length ? "flag" : "");
    const miss = h.points_missing;
    let text = "none";
    if (miss.length) {
      text = miss.slice(0, 8).map((p) => `${p.point}: ${p.missing}/${h.window_steps}`).join("; ");
      if (miss.length > 8) text += `; +${miss.length - 8} more points`;
    }
    row(dl, "Points missing readings", text, miss.length ? "flag" : "");
  }

  function showDiagnosis(d, fmt) {
    const box = $("diagnosis");
    box.replaceChildren();
    if (!d.available) {
      box.appendChild(el("p", "no diagnosis"));
      if (d.detail) box.appendChild(el("p", d.detail, "muted"));
      return;
    }
    box.appendChild(el("p", `${d.file}, written ${fmt(d.modified)}`, "muted"));
    const rows = d.effects.slice(0, 5).map((e) => [
      e.effect, e.zones.join(", ") || "all", e.confident ? "yes" : "no", num(e.score, 3),
      `${num(e.heldout_rms_before.mean, 3)} → ${num(e.heldout_rms_after.mean, 3)}`,
    ]);
    box.appendChild(table(["effect", "zones", "confident", "score",
                           "held-out RMS [K] before → after"], rows));
  }

  function zoneCard(zone, i, ctx) {
    const card = el("article", null, "zone");
    card.appendChild(el("h2", zone));
    const chart = el("div", null, "chart");
    chart.id = "chart-" + i;
    chart.dataset.zone = zone;
    card.appendChild(chart);
    if (ctx.forecast.problem) card.appendChild(el("p", "No forecast: " + ctx.forecast.problem, "flag"));
    const h = ctx.health.zones.find((z) => z.zone === zone);
    const g = ctx.gains.zones.find((z) => z.zone === zone);
    const dl = el("dl");
    dl.className = "zone-facts";
    row(dl, "Innovation RMS", h.innovation_steps
      ? `${num(h.innovation_rms, 3)} K over ${h.innovation_steps} steps` : "— (no step since the service started)");
    row(dl, "Missing measurements", `${h.missing_steps} of ${ctx.health.window_steps} steps`,
        h.missing_steps ? "flag" : "");
    row(dl, "Last measured", ctx.fmt(h.last_measured) || "never");
    row(dl, "Internal gains f_IG", `${num(g.online, 2)} W/m² online, last estimate ${num(g.last_estimate, 2)} W/m²`);
    let diag = "no diagnosis";
    if (ctx.diagnosis.available) {
      const mine = ctx.diagnosis.effects.filter((e) => e.confident && (!e.zones.length || e.zones.includes(zone)));
      diag = mine.length ? mine.map((e) => {
        const before = e.heldout_rms_before[zone], after = e.heldout_rms_after[zone];
        return before === undefined ? e.effect : `${e.effect} (${num(before, 3)} → ${num(after, 3)} K)`;
      }).join("; ") : "no confident effect in this zone";
    }
    row(dl, "Diagnosis", diag);
    card.appendChild(dl);
    return card;
  }

  function plotZone(zone, i, history, gains, forecast, fmt) {
    const j = history.zones.findIndex((z) => z.zone === zone);
    const x = history.times.map(fmt);
    const traces = [];
    const shapes = [];
    if (!forecast.problem) {
      const z = forecast.zones.find((f) => f.zone === zone);
      const fx = forecast.times.map(fmt);
      traces.push(
        { name: "interval lower", x: fx, y: z.lower, mode: "lines", line: { width: 0 },
          showlegend: false, hoverinfo: "skip" },
        { name: "90 % interval", x: fx, y: z.upper, mode: "lines", line: { width: 0 },
          fill: "tonexty", fillcolor: "rgba(31, 119, 180, 0.2)" },
        { name: "forecast", x: fx, y: z.mean, mode: "lines", line: { color: "#1f77b4" } },
        { name: "f_IG assumed", x: fx, y: z.internal_gains, mode: "lines", yaxis: "y2",
          line: { color: "#d62728", dash: "dot", width: 1 } });
      const t0 = fmt(forecast.issued);
      shapes.push({ type: "line", xref: "x", yref: "paper", x0: t0, x1: t0, y0: 0, y1: 1,
                    line: { color: "#888", dash: "dash", width: 1 } });
    }
    traces.push({ name: "measured", x, y: history.zones[j].measured, mode: "lines",
                  line: { color: "#222" }, connectgaps: false });
    const g = gains.zones.find((z) => z.zone === zone);
    if (gains.time) {
      traces.push({ name: "f_IG online", x: [fmt(gains.time)], y: [g.online], yaxis: "y2",
                    mode: "markers", marker: { color: "#d62728", size: 8 } });
    }
    const layout = {
      margin: { l: 50, r: 55, t: 28, b: 40 },
      xaxis: { type: "date" },
      yaxis: { title: { text: "°C" } },
      yaxis2: { title: { text: "f_IG [W/m²]" }, overlaying: "y", side: "right",
                showgrid: false, rangemode: "tozero", tickmode: "auto", nticks: 6 },
      legend: { orientation: "h", y: -0.18 },
      shapes,
    };
    Plotly.react("chart-" + i, traces, layout, { displaylogo: false, responsive: true });
  }

  // --- wiring ------------------------------------------------------------------------
  function init() {
    $("login").addEventListener("submit", (ev) => {
      ev.preventDefault();
      const token = $("token").value.trim();
      $("token").value = "";
      if (!token) return;
      sessionStorage.setItem(KEY, token);
      start();
    });
    $("logout").addEventListener("click", () => loggedOut(null));
    $("building").addEventListener("change", refresh);
    if (typeof Plotly === "undefined") {
      showError("The charting library did not load (/ui/plotly.min.js): install the Python " +
                "package plotly with the service (pip install 'zonecast[service]').");
      document.body.dataset.state = "error";
      return;
    }
    if (sessionStorage.getItem(KEY)) start();
    else document.body.dataset.state = "login";
  }

  init();
})();

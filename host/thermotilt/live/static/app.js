// The live view's page: one EventSource on /api/events. Its first event is
// the whole view, each later one the view with only the rows this page lacks
// (docs/live.md). Stable hooks for tests: #position[data-k][data-n][data-label],
// #positions li[data-label][data-status], #points[data-points],
// #temperature-chart[data-points][data-marks], #faults li[data-kind], #eta[data-seconds].
"use strict";

const CHART_HEIGHT = 260;
const SENSOR_CHART_HEIGHT = 200;
const FAULT_RED = "#e03131";

// Per sensor key: {key, columns: {t_s: [...], setpoint_c: [...], ...}}.
const series = new Map();
let view = null;
let temperatureChart = null;
const sensorCharts = new Map();
let shownFaults = 0;

const $ = (id) => document.getElementById(id);

function text(element, value) {
  element.textContent = value === null || value === undefined || value === "" ? "–" : String(value);
}

function duration(seconds) {
  const s = Math.round(seconds);
  if (s < 60) return `${s} s`;
  const minutes = Math.floor(s / 60);
  if (minutes < 60) return `${minutes} min ${String(s % 60).padStart(2, "0")} s`;
  return `${Math.floor(minutes / 60)} h ${String(minutes % 60).padStart(2, "0")} min`;
}

function clock(date) {
  return date.toLocaleTimeString([], { hour: "2-digit", minute: "2-digit", second: "2-digit" });
}

// --- series: the rows of the current position, grown by increments ---

function takeSeries(blocks) {
  const seen = new Set();
  for (const block of blocks) {
    seen.add(block.sensor);
    const known = series.get(block.sensor);
    if (!known || known.key !== block.key || block.start === 0) {
      series.set(block.sensor, { key: block.key, columns: block.columns });
      continue;
    }
    for (const [name, values] of Object.entries(block.columns)) {
      const column = known.columns[name];
      for (const value of values) column.push(value);
    }
  }
  for (const sensor of [...series.keys()]) {
    if (!seen.has(sensor)) series.delete(sensor);
  }
}

function firstSeries() {
  return series.values().next().value || null;
}

// --- charts ---

function faultMarksPlugin() {
  return {
    hooks: {
      draw: [
        (u) => {
          const marks = currentFaultMarks();
          const ctx = u.ctx;
          const dpr = window.devicePixelRatio || 1;
          ctx.save();
          ctx.strokeStyle = FAULT_RED;
          ctx.fillStyle = FAULT_RED;
          ctx.lineWidth = 2 * dpr;
          ctx.font = `${11 * dpr}px system-ui, sans-serif`;
          // uPlot leaves the alignment of the axis it drew last.
          ctx.textAlign = "left";
          ctx.textBaseline = "alphabetic";
          marks.forEach((mark, index) => {
            const x = u.valToPos(mark.t_s, "x", true);
            if (!Number.isFinite(x) || x < u.bbox.left - 1 || x > u.bbox.left + u.bbox.width + 1) return;
            ctx.beginPath();
            ctx.moveTo(x, u.bbox.top);
            ctx.lineTo(x, u.bbox.top + u.bbox.height);
            ctx.stroke();
            // Labels of marks close together stack downwards instead of overwriting each other.
            const y = u.bbox.top + (14 + 14 * (index % 4)) * dpr;
            const label = faultText(mark);
            const width = ctx.measureText(label).width;
            const right = u.bbox.left + u.bbox.width;
            ctx.fillText(label, x + 4 * dpr + width > right ? x - 4 * dpr - width : x + 4 * dpr, y);
          });
          ctx.restore();
        },
      ],
    },
  };
}

function currentFaultMarks() {
  if (!view || !view.current) return [];
  return view.faults.filter(
    (fault) => fault.t_s !== null && fault.position === (view.current.label ?? "") && fault.kind !== "failed"
  );
}

function chartWidth(element) {
  return Math.max(320, element.clientWidth || 800);
}

function makeTemperatureChart(element) {
  const options = {
    width: chartWidth(element),
    height: CHART_HEIGHT,
    scales: { x: { time: false } },
    axes: [{ label: "s since the position started" }, { label: "°C" }],
    series: [
      { label: "t (s)" },
      { label: "setpoint", stroke: "#495057", width: 1.5, dash: [6, 4] },
      { label: "inner face (chamber_c)", stroke: "#e8590c", width: 1.5 },
      { label: "outer face (outer_c)", stroke: "#1c7ed6", width: 1.5 },
    ],
    legend: { live: false },
    plugins: [faultMarksPlugin()],
  };
  return new uPlot(options, [[], [], [], []], element);
}

function makeSensorChart(element, name) {
  const options = {
    width: chartWidth(element),
    height: SENSOR_CHART_HEIGHT,
    scales: { x: { time: false }, X: { auto: true }, Y: { auto: true } },
    axes: [
      { label: "s since the position started" },
      { scale: "X", label: "X (LSB)", stroke: "#2b8a3e" },
      { scale: "Y", label: "Y (LSB)", side: 1, stroke: "#862e9c", grid: { show: false } },
    ],
    series: [
      { label: "t (s)" },
      { label: `${name} X (ax_filt)`, scale: "X", stroke: "#2b8a3e", width: 1.5 },
      { label: `${name} Y (ay_filt)`, scale: "Y", stroke: "#862e9c", width: 1.5 },
    ],
    legend: { live: false },
    plugins: [faultMarksPlugin()],
  };
  return new uPlot(options, [[], [], []], element);
}

function sensorName(key) {
  const sensor = (view?.sensors || []).find((row) => row.key === key);
  return sensor && sensor.id ? sensor.id : "sensor";
}

function drawCharts() {
  const chamber = firstSeries();
  const element = $("temperature-chart");
  if (!temperatureChart) temperatureChart = makeTemperatureChart(element);
  const c = chamber ? chamber.columns : null;
  temperatureChart.setData(c ? [c.t_s, c.setpoint_c, c.chamber_c, c.outer_c] : [[], [], [], []]);
  const points = c ? c.t_s.length : 0;
  element.dataset.points = String(points);
  element.dataset.marks = String(currentFaultMarks().length);
  $("points").dataset.points = String(points);
  text($("points"), points.toLocaleString());
  $("run-time").textContent = points ? `${duration(c.t_s[points - 1] || 0)} of the run` : "no rows yet";
  drawSensorCharts();
}

function drawSensorCharts() {
  const holder = $("sensor-charts");
  for (const [key, entry] of sensorCharts) {
    if (!series.has(key)) {
      entry.chart.destroy();
      entry.box.remove();
      sensorCharts.delete(key);
    }
  }
  if (series.size === 0 && !holder.querySelector(".no-data")) {
    holder.innerHTML = '<div class="no-data">no rows of this position yet</div>';
  }
  for (const [key, entry] of series) {
    let chart = sensorCharts.get(key);
    if (!chart) {
      holder.querySelector(".no-data")?.remove();
      const box = document.createElement("div");
      box.className = "sensor-chart";
      box.dataset.sensor = key;
      const title = document.createElement("h3");
      title.textContent = sensorName(key);
      const plot = document.createElement("div");
      box.append(title, plot);
      holder.append(box);
      chart = { box, chart: makeSensorChart(plot, sensorName(key)) };
      sensorCharts.set(key, chart);
    }
    const c = entry.columns;
    chart.chart.setData([c.t_s, c.ax_filt, c.ay_filt]);
    chart.box.dataset.points = String(c.t_s.length);
  }
}

window.addEventListener("resize", () => {
  if (temperatureChart) temperatureChart.setSize({ width: chartWidth($("temperature-chart")), height: CHART_HEIGHT });
  for (const entry of sensorCharts.values()) {
    entry.chart.setSize({ width: chartWidth(entry.box), height: SENSOR_CHART_HEIGHT });
  }
});

// --- the rest of the view ---

function drawHeader() {
  const folder = $("folder");
  folder.textContent = view.folder;
  folder.dataset.folder = view.folder;
  document.title = `ThermoTilt live: ${view.title || view.folder}`;
  $("kind").textContent = [view.kind, view.rig].filter(Boolean).join(" · ") || "waiting";
  $("updated").textContent = `updated ${clock(new Date())}`;
  const problem = $("problem");
  problem.hidden = !view.problem;
  problem.textContent = view.problem ? `Waiting for the folder: ${view.problem}` : "";
}

function drawPosition() {
  const current = view.current || {};
  const card = $("position");
  card.dataset.k = current.k ?? "";
  card.dataset.n = current.n ?? "";
  card.dataset.label = current.label ?? "";
  card.dataset.status = current.status ?? "";
  // A run folder is one run, not a position of a plan.
  const plan = current.k !== null && current.k !== undefined;
  $("position-plan").hidden = !plan;
  $("position-run").hidden = plan;
  $("position-title").textContent = plan || !view.kind ? "Position" : "Run";
  text($("position-k"), current.k);
  text($("position-n"), current.n);
  text($("position-run"), current.label);
  text($("position-label"), plan ? current.label : view.rig);
  const chip = $("position-status");
  chip.textContent = current.status || "";
  chip.dataset.status = current.status || "";
}

function drawEta() {
  const eta = $("eta");
  eta.dataset.seconds = view.eta_s ?? "";
  const running = (view.positions || []).some((position) => position.status === "running");
  if (view.eta_s === null || view.eta_s === undefined) {
    eta.textContent = view.kind === "run" ? "–" : running ? "estimating…" : "not running";
    $("eta-at").textContent = "";
  } else if (view.eta_s === 0) {
    eta.textContent = "finished";
    $("eta-at").textContent = "every position has run";
  } else {
    eta.textContent = duration(view.eta_s);
    $("eta-at").textContent = `ends about ${clock(new Date(Date.now() + view.eta_s * 1000))}`;
  }
}

// What a list showed last, so that an unchanged one is not drawn again.
const drawn = { positions: "", sensors: "" };

function drawPositions() {
  const panel = $("positions-panel");
  const positions = view.positions || [];
  panel.hidden = positions.length === 0;
  const signature = JSON.stringify([positions, view.current && view.current.label]);
  if (signature === drawn.positions) return;
  drawn.positions = signature;
  const list = $("positions");
  list.replaceChildren(
    ...positions.map((position) => {
      const item = document.createElement("li");
      item.dataset.label = position.label;
      item.dataset.status = position.status;
      item.dataset.current = String(view.current && view.current.label === position.label);
      const wall = position.wall_seconds ? `, ${duration(position.wall_seconds)}` : "";
      item.title = `${position.label}: ${position.status}${wall}`;
      const k = document.createElement("span");
      k.className = "k";
      k.textContent = `${position.k}`;
      item.append(k, document.createTextNode(position.label));
      return item;
    })
  );
}

function faultText(fault) {
  return [fault.sensor, fault.board].filter(Boolean).map((who) => `${who}: `).join("") + fault.text;
}

function faultItem(fault) {
  const item = document.createElement("li");
  item.dataset.kind = fault.kind;
  item.dataset.position = fault.position;
  const kind = document.createElement("span");
  kind.className = "fault-kind";
  kind.textContent = fault.kind;
  const where = document.createElement("span");
  where.className = "fault-where";
  const at = fault.t_s === null ? "" : ` · ${fault.t_s.toFixed(1)} s`;
  where.textContent = `${fault.position || "run"}${at}`;
  const what = document.createElement("span");
  what.className = "fault-text";
  what.textContent = faultText(fault);
  item.append(kind, where, what);
  return item;
}

function drawFaults() {
  const faults = view.faults || [];
  $("fault-card").dataset.count = String(faults.length);
  text($("fault-count"), faults.length);
  const last = faults[faults.length - 1];
  $("last-fault").textContent = last ? `${last.position || "run"}: ${last.text}` : "none";
  if (faults.length === shownFaults) return;
  const list = $("faults");
  const items = faults.map(faultItem).reverse();
  items.slice(0, faults.length - shownFaults).forEach((item) => item.classList.add("fresh"));
  list.replaceChildren(...(items.length ? items : [Object.assign(document.createElement("li"), { className: "empty", textContent: "none so far" })]));
  shownFaults = faults.length;
}

function drawSensors() {
  // The registry's columns are `thermotilt sensors`' own, as the server sends them.
  const columns = view.registry_columns || [];
  const signature = JSON.stringify([columns, view.sensors || []]);
  if (signature === drawn.sensors) return;
  drawn.sensors = signature;
  const head = $("sensors").querySelector("thead tr");
  head.replaceChildren(
    ...["sensor", ...columns].map((column) => Object.assign(document.createElement("th"), { textContent: column }))
  );
  const body = $("sensors").querySelector("tbody");
  body.replaceChildren(
    ...(view.sensors || []).map((sensor) => {
      const row = document.createElement("tr");
      row.dataset.sensor = sensor.id;
      const name = document.createElement("td");
      name.className = "sensor-id";
      name.textContent = sensor.id || "(no sensor ID)";
      row.append(name);
      if (!sensor.registry) {
        const none = document.createElement("td");
        none.className = "registry-none";
        none.colSpan = Math.max(1, columns.length);
        none.textContent = "—";
        row.append(none);
        row.dataset.registry = "none";
        return row;
      }
      row.dataset.registry = "line";
      for (const column of columns) {
        const cell = document.createElement("td");
        cell.textContent = sensor.registry[column] ?? "-";
        row.append(cell);
      }
      return row;
    })
  );
}

function apply(document_) {
  view = document_;
  takeSeries(view.series || []);
  drawHeader();
  drawPosition();
  drawEta();
  drawPositions();
  drawFaults();
  drawSensors();
  drawCharts();
}

// --- the connection ---

function connect() {
  const events = new EventSource("/api/events");
  events.onopen = () => {
    document.body.dataset.connection = "live";
    $("connection").textContent = "live";
  };
  events.onmessage = (message) => {
    document.body.dataset.connection = "live";
    $("connection").textContent = "live";
    apply(JSON.parse(message.data));
  };
  events.onerror = () => {
    // EventSource tries again by itself; a campaign's --serve ends with its command.
    const state = events.readyState === EventSource.CLOSED ? "closed" : "reconnecting";
    document.body.dataset.connection = state;
    $("connection").textContent =
      state === "closed" ? "disconnected (the server stopped)" : "reconnecting (the serving command may have ended)";
  };
}

connect();

/* hapstab explorer: the four plots (uPlot), their CSV and PNG.
 *
 * Each plot is drawn from the API's JSON answer by a function below; a plot keeps its
 * table (the numbers drawn, for CSV) and its markers (drawn on the canvas by a hook, and
 * written into the figure's data- attributes so that a test can read them).
 */
"use strict";

const HapstabPlots = (() => {
  const COLORS = { line: "#1f5fbf", line2: "#c25400", line3: "#6b4fbb", band: "rgba(31,95,191,.16)",
                   ok: "#19794a", bad: "#b3261e", grid: "#e8ebf0", ref: "#8a94a6" };
  const plots = {};   // key -> {u, table, markers}

  function fmt(v) {
    if (v == null || !isFinite(v)) return "";
    const a = Math.abs(v);
    if (a !== 0 && (a >= 1e5 || a < 1e-3)) return v.toExponential(2);
    return +v.toPrecision(4) + "";
  }

  function axis(label, extra) {
    return Object.assign({ label, labelSize: 16, size: 46, stroke: "#4a5466", font: "11px system-ui, sans-serif",
                           labelFont: "11px system-ui, sans-serif",
                           grid: { stroke: COLORS.grid, width: 1 }, ticks: { stroke: COLORS.grid, width: 1 },
                           values: (u, vals) => vals.map(fmt) }, extra || {});
  }

  // markers: [{x, y, color, label, vline, hline, scale}] drawn after the series
  function drawMarkers(u) {
    const p = plots[u.root.parentNode.dataset.key];
    if (!p || !p.markers) return;
    const ctx = u.ctx, dpr = devicePixelRatio || 1;
    ctx.save();
    ctx.beginPath(); ctx.rect(u.bbox.left, u.bbox.top, u.bbox.width, u.bbox.height); ctx.clip();
    for (const m of p.markers) {
      if (m.x == null || !isFinite(m.x)) continue;
      const X = u.valToPos(m.x, "x", true);
      const Y = m.y == null || !isFinite(m.y) ? null : u.valToPos(m.y, m.scale || "y", true);
      ctx.strokeStyle = m.color; ctx.fillStyle = m.color; ctx.lineWidth = 1.5 * dpr;
      if (m.vline) {
        ctx.setLineDash([4 * dpr, 3 * dpr]); ctx.beginPath();
        ctx.moveTo(X, u.bbox.top); ctx.lineTo(X, u.bbox.top + u.bbox.height); ctx.stroke();
        ctx.setLineDash([]);
      }
      if (m.hline && Y != null) {
        ctx.setLineDash([4 * dpr, 3 * dpr]); ctx.beginPath();
        ctx.moveTo(u.bbox.left, Y); ctx.lineTo(u.bbox.left + u.bbox.width, Y); ctx.stroke();
        ctx.setLineDash([]);
      }
      if (Y != null && !m.hline) {
        ctx.beginPath(); ctx.arc(X, Y, 5 * dpr, 0, 2 * Math.PI); ctx.fill();
        ctx.strokeStyle = "#fff"; ctx.lineWidth = 1.5 * dpr; ctx.stroke();
      }
      if (m.label) {
        ctx.font = `${11 * dpr}px system-ui, sans-serif`; ctx.fillStyle = m.color;
        const ty = Y != null ? Y - 8 * dpr : u.bbox.top + 12 * dpr;
        const right = X > u.bbox.left + u.bbox.width * 0.7;
        ctx.textAlign = right ? "right" : "left";
        ctx.fillText(m.label, X + (right ? -7 : 7) * dpr, ty);
      }
    }
    ctx.restore();
  }

  function render(key, opts, data, table, markers) {
    const fig = document.getElementById("plot-" + key);
    const box = fig.querySelector(".canvas");
    box.dataset.key = key;
    const old = plots[key];
    if (old && old.u) old.u.destroy();
    box.replaceChildren();
    const w = Math.max(box.clientWidth, 200), h = Math.max(box.clientHeight - 20, 120);
    const o = Object.assign({ width: w, height: h, cursor: { drag: { x: false, y: false } },
                              legend: { show: true, live: false },
                              hooks: { draw: [drawMarkers] } }, opts);
    // the figure node is the hook's way back to its markers
    const holder = document.createElement("div");
    holder.dataset.key = key;
    box.appendChild(holder);
    plots[key] = { table, markers, title: fig.querySelector(".title").textContent };
    plots[key].u = new uPlot(o, data, holder);
    const n = data[0] ? data[0].length : 0;
    fig.dataset.points = String(n);
    for (const m of markers || []) if (m.name) {
      fig.dataset[m.name + "X"] = String(m.x); fig.dataset[m.name + "Y"] = String(m.y);
    }
  }

  function note(key, text) {
    const fig = document.getElementById("plot-" + key);
    const box = fig.querySelector(".canvas");
    if (plots[key] && plots[key].u) plots[key].u.destroy();
    plots[key] = null;
    fig.dataset.points = "0";
    const d = document.createElement("div");
    d.className = "note"; d.textContent = text;
    box.replaceChildren(d);
  }

  // ---------------------------------------------------------------- the four plots
  // K_max against T (or the rate) at the current delay; the current T and K marked
  function boundary(ans, cur) {
    const rate = cur.rateMode;
    const T = ans.period_s;
    const K = ans.critical_stiffness[0];
    let xs = T.map((t) => (rate ? 1 / t : t * 1e3));
    let ys = K.slice();
    if (rate) { xs = xs.reverse(); ys = ys.reverse(); }
    const xcur = rate ? 1 / cur.period_s : cur.period_s * 1e3;
    const xl = rate ? "sampling rate (Hz)" : "period T (ms)";
    const markers = [{ name: "current", x: xcur, y: cur.kmax, color: COLORS.bad, vline: true,
                       label: `K_max ${fmt(cur.kmax)} N/m` }];
    if (cur.stiffness != null) markers.push({ x: xs[0], y: cur.stiffness, hline: true, color: COLORS.ok });
    render("boundary", {
      scales: { x: { time: false, distr: 3 }, y: { range: (u, lo, hi) => [0, hi * 1.08 || 1] } },
      axes: [axis(xl), axis("K_max (N/m)")],
      series: [{ label: xl }, { label: `K_max, delay ${cur.delayLabel}`, stroke: COLORS.line, width: 2 }],
    }, [xs, ys], { headers: [rate ? "rate_hz" : "period_s", "critical_stiffness_N_per_m"],
                   rows: xs.map((x, i) => [rate ? x : x / 1e3, ys[i]]) }, markers);
  }

  // the stable K range for each B (the first stable interval; more are listed in the CSV)
  function region(ans, cur) {
    const B = [], lo = [], hi = [], rows = [];
    let more = false;
    for (const r of ans.rows) {
      const iv = r.stable_intervals || [];
      B.push(r.virtual_damping);
      lo.push(iv.length ? iv[0][0] : null);
      hi.push(iv.length ? iv[0][1] : null);
      if (iv.length > 1) more = true;
      rows.push([r.virtual_damping, iv.map((p) => p.join(":")).join(" ")]);
    }
    const stable = cur.verdict === "stable";
    render("region", {
      scales: { x: { time: false }, y: { range: () => ans.K_range } },
      axes: [axis("virtual damping B (N·s/m)"), axis("K (N/m)")],
      series: [{ label: "B" },
               { label: "lowest stable K", stroke: COLORS.line, width: 1 },
               { label: more ? "K_max(B), first stable interval" : "K_max(B)", stroke: COLORS.line, width: 2 }],
      bands: [{ series: [2, 1], fill: COLORS.band }],
    }, [B, lo, hi], { headers: ["virtual_damping_N_s_per_m", "stable_intervals_K_N_per_m"], rows },
    [{ name: "marker", x: cur.B, y: cur.stiffness, color: stable ? COLORS.ok : COLORS.bad,
       label: `K=${fmt(cur.stiffness)}, B=${fmt(cur.B)}` }]);
  }

  // position (mm) and the controller's force (N) of each device against time
  function simulate(ans) {
    const s = ans.series;
    if (!s || !s.time_s) { note("simulate", "this server's simulate gives no time series (--series)"); return; }
    const t = s.time_s;
    const xk = Object.keys(s).filter((k) => /^x_.*_m$/.test(k));
    // the controller's force beside one device's position; two devices: positions only
    const uk = xk.length > 1 ? [] : Object.keys(s).filter((k) => /^u_.*_N$/.test(k));
    const series = [{ label: "t (s)" }], data = [t];
    const pal = [COLORS.line, COLORS.line3, COLORS.line2, "#2a9d8f"];
    xk.forEach((k, i) => {
      series.push({ label: k.slice(2, -2) + " x (mm)", stroke: pal[i], width: 1.6, scale: "mm" });
      data.push(s[k].map((v) => v * 1e3));
    });
    uk.forEach((k, i) => {
      series.push({ label: k.slice(2, -2) + " force (N)", stroke: pal[(i + 2) % 4], width: 1,
                    scale: "N" });
      data.push(s[k]);
    });
    const keys = ["time_s", ...xk, ...uk];
    const axes = [axis("time (s)"), axis("position (mm)", { scale: "mm" })];
    if (uk.length) axes.push(axis("force (N)", { scale: "N", side: 1, grid: { show: false } }));
    render("simulate", {
      scales: { x: { time: false } },
      axes,
      series,
    }, data, { headers: keys, rows: t.map((_, i) => keys.map((k) => s[k][i])) },
    [{ name: "verdict", x: null, y: null, color: COLORS.ref }]);
  }

  // the passivity margin (damping to spare) over frequency; its minimum marked
  function passivity(ans) {
    const c = ans.margin_curve;
    if (!c) { note("passivity", "no margin curve in the answer"); return; }
    const f = c.frequency_hz, m = c.margin;
    const ok = ans.passive;
    render("passivity", {
      scales: { x: { time: false },
                y: { range: (u, lo, hi) => { const a = Math.min(0, lo), b = Math.max(0, hi), p = 0.06 * (b - a || 1); return [a - (a < 0 ? p : 0), b + p]; } } },
      axes: [axis("frequency (Hz)"), axis("margin (N·s/m)")],
      series: [{ label: "f (Hz)" }, { label: "passivity margin", stroke: COLORS.line, width: 2,
                                      fill: ok ? "rgba(25,121,74,.08)" : "rgba(179,38,30,.08)" }],
    }, [f, m], { headers: ["frequency_hz", "margin"], rows: f.map((x, i) => [x, m[i]]) },
    [{ x: f[0], y: 0, hline: true, color: COLORS.ref },
     { name: "worst", x: ans.worst_frequency_hz, y: ans.margin, color: ok ? COLORS.ok : COLORS.bad,
       label: `min ${fmt(ans.margin)} at ${fmt(ans.worst_frequency_hz)} Hz` }]);
  }

  // ---------------------------------------------------------------- downloads
  function csv(key) {
    const p = plots[key];
    if (!p || !p.table) return null;
    const q = (v) => (v == null ? "" : typeof v === "string" && /[",\n]/.test(v) ? `"${v.replace(/"/g, '""')}"` : String(v));
    return [p.table.headers.join(","), ...p.table.rows.map((r) => r.map(q).join(","))].join("\n") + "\n";
  }

  function png(key) {
    const p = plots[key];
    if (!p || !p.u) return null;
    const src = p.u.ctx.canvas, dpr = devicePixelRatio || 1;
    const c = document.createElement("canvas");
    const head = Math.round(22 * dpr);
    c.width = src.width; c.height = src.height + head;
    const ctx = c.getContext("2d");
    ctx.fillStyle = "#fff"; ctx.fillRect(0, 0, c.width, c.height);
    ctx.fillStyle = "#1d2430"; ctx.font = `${13 * dpr}px system-ui, sans-serif`;
    ctx.fillText(p.title, 8 * dpr, 15 * dpr);
    ctx.drawImage(src, 0, head);
    return c.toDataURL("image/png");
  }

  function resize() {
    for (const key of Object.keys(plots)) {
      const p = plots[key];
      if (!p || !p.u) continue;
      const box = document.querySelector(`#plot-${key} .canvas`);
      p.u.setSize({ width: Math.max(box.clientWidth, 200), height: Math.max(box.clientHeight - 20, 120) });
    }
  }

  return { boundary, region, simulate, passivity, note, csv, png, resize, plots };
})();

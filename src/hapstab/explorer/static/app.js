/* hapstab explorer: the form (built from GET /api/v1/schema), the live answers, the URL.
 *
 * Every input change (debounced) sends the commands the page shows to POST /api/v1/{command};
 * a superseded request is aborted (AbortController) and carries X-Hapstab-Channel / -Seq so
 * that the server can skip it. The page keeps only what the user changed from the CLI's
 * defaults: that is what the URL, the requests and the copied command carry.
 */
"use strict";

(() => {
  const $ = (s, root = document) => root.querySelector(s);
  const API = "api/v1/";
  const DEBOUNCE_MS = 30;
  const PAGE = Math.random().toString(36).slice(2, 10);   // this tab's channels
  const CURVE_POINTS = 400;      // the passivity margin curve
  // the delay margin's search stops after this many seconds (a long delay's verdict is an
  // eigenvalue problem of ~2 states per sample): the page says how far it searched
  const MARGIN_SECONDS = 2;
  const REGION_RESOLUTION = 48;  // K-B rows of B (each row's K intervals are exact)
  const SWEEP = 25;              // periods of the K_max-against-T plot, T/4 ... 4T
  const NET = HapstabNetwork;                             // the network card (network.js)
  const PAGE_FIELDS = ["_kwin", "_bwin", ...NET.FIELDS];
  const MAIN = {
    hve: [["Device", ["mass", "damping"]], ["Operator", ["operator"]],
          ["Sampling and delay", ["period", "delay"]], ["Controller", ["stiffness", "virtual-damping"]]],
    peb: [["Master and slave", ["master-mass", "master-damping", "slave-mass", "slave-damping"]],
          ["Operator and environment", ["operator", "environment"]],
          ["Sampling and delay", ["period", "delay"]], ["Controller", ["stiffness", "virtual-damping"]]],
  };
  // one field, two ways to give it: a unit switch beside the input
  const ALT = { period: { other: "rate", units: ["T (s)", "rate (Hz)"] },
                delay: { other: "delay-s", units: ["samples", "seconds"] } };
  const ALT_OF = { rate: "period", "delay-s": "delay" };
  const LABELS = { "virtual-damping": "B (virtual damping)", stiffness: "K (stiffness)",
                   period: "Sampling", delay: "Delay" };
  const UNITS = { mass: "kg", "master-mass": "kg", "slave-mass": "kg", damping: "N·s/m",
                  "master-damping": "N·s/m", "slave-damping": "N·s/m", stiffness: "N/m",
                  "virtual-damping": "N·s/m", "slave-virtual-damping": "N·s/m", friction: "N",
                  "master-friction": "N", "slave-friction": "N", duration: "s", x0: "m", rest: "m",
                  wall: "m", saturation: "N", resolution: "m", operator: "Z", environment: "Z",
                  // a force spec (step:F, sine:F,Hz): newtons, not the sine's Hz of its help
                  force: "N", "environment-force": "N" };
  const PAGE_DEFAULTS = { hve: { stiffness: "50" }, peb: { stiffness: "5" } };
  const CLOSED = ["colgate", "gil", "eq18", "gil2004", "eq29", "eq34"];
  // options a command varies itself (the CLI refuses a given value: cli/study.py VARIED)
  const VARIED = { region: ["virtual-damping"], "best-damping": ["virtual-damping"] };
  const NOT_SENT = new Set(["json", "csv", "plot", "study", "variant", "dense", "series", "curve"]);

  let schema = null;
  const state = { kind: "hve", values: {} };   // values: name -> text, only those changed
  const shown = {};                            // command -> last good answer shown
  const ctrls = {};
  let SEQ = 0, timer = null, NETSEQ = 0;

  // ------------------------------------------------------------------ schema helpers
  const cmds = () => schema.kinds[state.kind].commands;
  const optsOf = (command) => cmds()[command] || [];
  const has = (command, name) => optsOf(command).some((o) => o.name === name);
  const optByName = {};   // kind -> name -> opt (loop options and simulate's)

  function loopOptions(kind) {
    const c = schema.kinds[kind].commands;
    const names = (k) => new Set((c[k] || []).map((o) => o.name));
    const sets = ["kmax", "check", "simulate"].filter((k) => c[k]).map(names);
    return (c.kmax || []).filter((o) => sets.every((s) => s.has(o.name)) && !NOT_SENT.has(o.name));
  }
  function simOptions(kind) {
    const loop = new Set(loopOptions(kind).map((o) => o.name));
    return (schema.kinds[kind].commands.simulate || [])
      .filter((o) => !loop.has(o.name) && !NOT_SENT.has(o.name) && o.name !== "stiffness");
  }
  function indexOptions(kind) {
    const m = {};
    for (const c of Object.values(schema.kinds[kind].commands)) for (const o of c) if (!m[o.name]) m[o.name] = o;
    for (const o of [...loopOptions(kind), ...simOptions(kind)]) m[o.name] = o;
    optByName[kind] = m;
  }
  const opt = (name) => optByName[state.kind][name];
  function defaultText(name) {
    const pd = PAGE_DEFAULTS[state.kind][name];
    if (pd !== undefined) return pd;
    const o = opt(name);
    return !o || o.default == null || o.type === "flag" ? "" : String(o.default);
  }
  const value = (name) => (name in state.values ? state.values[name] : defaultText(name));
  const unitOf = (o) => UNITS[o.name] || o.unit ||
    ((o.help.match(/\b(?:in|,)\s+(kg|N\*s\/m|N\/m|N|Hz|m)\b/) || [])[1] || "").replace("N*s/m", "N·s/m");

  // the JSON value of a text the user typed: a plain number as a number, anything else as
  // the text, which the CLI's own type parses ("1kHz", "20ms") or refuses with its message
  function jsonValue(o, text) {
    if (o.type === "flag") return text === "true";
    const t = text.trim();
    // (a number JSON cannot carry, 1e400, goes as the text: the CLI says "must be finite")
    if ((o.type === "float" || o.type === "int") && /^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$/.test(t) &&
        isFinite(Number(t))) return Number(t);
    return t;
  }

  // the options of one command: the loop's, K where it takes one, simulate's own
  function optionsFor(command, extra) {
    const out = {};
    const allowed = new Set(optsOf(command).map((o) => o.name));
    const sim = new Set(simOptions(state.kind).map((o) => o.name));
    const names = new Set(Object.keys(state.values));
    if (allowed.has("stiffness")) names.add("stiffness");
    for (const name of names) {
      if (!allowed.has(name) || NOT_SENT.has(name) || (sim.has(name) && command !== "simulate") ||
          (VARIED[command] || []).includes(name)) continue;
      const o = optByName[state.kind][name];
      const text = value(name);
      if (text === "" && o.type !== "flag") continue;
      out[name] = jsonValue(o, text);
    }
    // an extra period (or rate, delay, delay-s) replaces the field's value both ways: the
    // CLI refuses --period beside --rate
    for (const k of Object.keys(extra || {})) {
      const pair = ALT[k] ? ALT[k].other : ALT_OF[k];
      if (pair) delete out[pair];
    }
    return Object.assign(out, extra || {});
  }

  // the loop's options the user set that COMMAND does not take (boundary peb has no
  // --delay-forward): its answer would be another loop's, so the page does not ask for it
  function unavailable(command, ignore = []) {
    if (!cmds()[command]) return `not available for this model: no "hapstab ${command} ${state.kind}"`;
    const allowed = new Set(optsOf(command).map((o) => o.name));
    const loop = new Set(loopOptions(state.kind).map((o) => o.name));
    const missing = Object.keys(state.values).filter((n) => loop.has(n) && !allowed.has(n) &&
      state.values[n] !== "" && !(VARIED[command] || []).includes(n) && !ignore.includes(n));
    if (!missing.length) return null;
    return `not available for this model: hapstab ${command} ${state.kind} takes no ` +
      missing.map((n) => "--" + n).join(", ");
  }

  // ------------------------------------------------------------------ the form
  function fieldRow(o, name) {
    const alt = ALT[name];
    const div = document.createElement("div");
    div.className = "field"; div.dataset.name = name;
    const id = "f-" + name;
    const label = document.createElement("label");
    label.htmlFor = id; label.textContent = LABELS[name] || o.name.replace(/-/g, " ");
    label.title = (o.flags || []).join(", ") + (o.help ? " — " + o.help : "");
    let input;
    if (o.type === "choice") {
      input = document.createElement("select");
      for (const c of o.choices) { const op = document.createElement("option"); op.value = op.textContent = c; input.appendChild(op); }
      if (o.default == null) { const op = document.createElement("option"); op.value = ""; op.textContent = "–"; input.prepend(op); }
    } else if (o.type === "flag") {
      input = document.createElement("input"); input.type = "checkbox";
    } else {
      input = document.createElement("input"); input.type = "text"; input.inputMode = "decimal";
      input.placeholder = o.default == null ? (o.required ? "required" : "–") : String(o.default);
    }
    input.id = id; input.name = name; input.title = o.help || "";
    const unit = document.createElement("span"); unit.className = "unit";
    if (alt) {
      const sel = document.createElement("select"); sel.id = id + "-unit"; sel.setAttribute("aria-label", name + " given as");
      [name, alt.other].forEach((v, i) => { const op = document.createElement("option"); op.value = v; op.textContent = alt.units[i]; sel.appendChild(op); });
      sel.addEventListener("change", () => switchAlt(name, sel.value));
      unit.appendChild(sel);
    } else unit.textContent = unitOf(o);
    const msg = document.createElement("div"); msg.className = "msg"; msg.setAttribute("role", "alert");
    div.append(label, input, unit, msg);
    input.addEventListener(o.type === "choice" || o.type === "flag" ? "change" : "input", () => onInput(input));
    return div;
  }

  function buildForm() {
    const main = $("#main-fields"), more = $("#more-fields");
    main.replaceChildren(); more.replaceChildren();
    const used = new Set(["rate", "delay-s"]);
    for (const [title, names] of MAIN[state.kind]) {
      const h = document.createElement("div"); h.className = "group-title"; h.textContent = title;
      main.appendChild(h);
      for (const name of names) {
        const o = opt(name);
        if (!o) continue;
        main.appendChild(fieldRow(o, name)); used.add(name);
      }
    }
    const groups = [["Loop", loopOptions(state.kind)], ["Simulation", simOptions(state.kind)]];
    for (const [title, list] of groups) {
      const h = document.createElement("div"); h.className = "group-title"; h.textContent = title;
      more.appendChild(h);
      for (const o of list) if (!used.has(o.name)) { more.appendChild(fieldRow(o, o.name)); used.add(o.name); }
    }
    for (const f of PAGE_FIELDS) $("#f-" + f).oninput = (e) => onInput(e.target);
    fillForm();
  }

  function fillForm() {
    for (const f of NET.FIELDS) $("#f-" + f).value = state.values[f] || "";
    for (const div of document.querySelectorAll("#form .field")) {
      const name = div.dataset.name;
      const input = $("#f-" + name);
      if (PAGE_FIELDS.includes(name)) { input.value = state.values[name] || ""; continue; }
      const alt = ALT[name];
      const active = alt && alt.other in state.values ? alt.other : name;
      if (alt) $("#f-" + name + "-unit").value = active;
      const o = opt(active);
      if (input.type === "checkbox") input.checked = value(active) === "true";
      else input.value = active === name || active in state.values ? value(active) : "";
      input.placeholder = o && o.default != null ? String(o.default) : input.placeholder;
    }
  }

  function activeName(input) {
    const name = input.name, alt = ALT[name];
    return alt ? $("#f-" + name + "-unit").value : name;
  }

  function onInput(input) {
    const name = activeName(input);
    const text = input.type === "checkbox" ? String(input.checked) : input.value;
    const dflt = PAGE_FIELDS.includes(name) ? "" : defaultText(name);
    if (text === dflt || (input.type === "checkbox" && text === "false")) delete state.values[name];
    else state.values[name] = text;
    if (NET.FIELDS.includes(name)) scheduleNet(); else schedule();
  }

  // period <-> rate, samples <-> seconds: converted with the last answer's loop
  function switchAlt(name, to) {
    const other = ALT[name].other, from = to === name ? other : name;
    const loop = shown.kmax && shown.kmax.inputs && shown.kmax.inputs.loop;
    delete state.values[from];
    if (loop) {
      const conv = { rate: 1 / loop.period_s, period: loop.period_s,
                     "delay-s": loop.delay_s, delay: loop.delay_samples }[to];
      if (conv != null && isFinite(conv)) state.values[to] = String(+conv.toPrecision(12));
    }
    if (state.values[to] === defaultText(to)) delete state.values[to];
    fillForm(); schedule();
  }

  function setKind(kind) {
    if (kind === state.kind) return;
    const keep = {};
    indexOptions(kind);
    for (const [k, v] of Object.entries(state.values))
      if (PAGE_FIELDS.includes(k) || ((optByName[kind][k]) && k !== "stiffness")) keep[k] = v;
    state.kind = kind; state.values = keep;
    for (const k of Object.keys(shown)) delete shown[k];
    buildForm(); schedule();
  }

  // ------------------------------------------------------------------ URL state
  function writeUrl() {
    const q = new URLSearchParams();
    q.set("kind", state.kind);
    for (const [k, v] of Object.entries(state.values)) q.set(k, v);
    history.replaceState(null, "", location.pathname + "?" + q.toString());
  }
  function readUrl() {
    const q = new URLSearchParams(location.search);
    if (![...q.keys()].length && schema.study && schema.kinds[schema.study.kind]) {
      state.kind = schema.study.kind;
      indexOptions(state.kind);
      for (const [k, v] of Object.entries(schema.study.options || {})) state.values[k.replace(/_/g, "-")] = String(v);
      return;
    }
    const kind = q.get("kind");
    if (kind && schema.kinds[kind]) state.kind = kind;
    indexOptions(state.kind);
    for (const [k, v] of q) if (k !== "kind" && (optByName[state.kind][k] || PAGE_FIELDS.includes(k))) state.values[k] = v;
  }

  // ------------------------------------------------------------------ requests
  let updating = false;                     // a change is waiting for, or in, update()
  function schedule() {
    clearTimeout(timer);
    updating = true;
    document.body.dataset.pending = "1";     // a test waits for this to go
    timer = setTimeout(update, DEBOUNCE_MS);
  }

  let inflight = 0;
  function busy(delta) {
    inflight += delta;
    const s = $("#status");
    if (inflight > 0) { s.className = "busy"; s.textContent = "computing…"; }
    else if (s.className === "busy") { s.className = "idle"; s.textContent = "up to date"; }
  }

  // live(): whether the answer is still wanted (default: no later change of the page)
  async function call(channel, command, options, seq, live = () => seq === SEQ) {
    if (ctrls[channel]) ctrls[channel].abort();
    const ac = new AbortController();
    ctrls[channel] = ac;
    busy(+1);
    document.querySelectorAll(`[data-channel="${channel}"]`).forEach((e) => e.classList.add("busy"));
    try {
      const r = await fetch(API + command, {
        method: "POST", signal: ac.signal,
        headers: { "Content-Type": "application/json", "X-Hapstab-Channel": PAGE + ":" + channel,
                   "X-Hapstab-Seq": String(seq) },
        body: JSON.stringify({ kind: state.kind, options }),
      });
      let body = null;
      try { body = await r.json(); } catch (e) { body = { error: `HTTP ${r.status}: not JSON` }; }
      if (!live() || r.status === 409) return { superseded: true };
      if (!r.ok) return { error: body.error || `HTTP ${r.status}`, parameter: body.parameter, status: r.status };
      return { ok: body };
    } catch (e) {
      if (e.name === "AbortError" || !live()) return { superseded: true };
      return { error: `the explorer's server does not answer (${e.message})`, parameter: null };
    } finally {
      busy(-1);
      if (ctrls[channel] === ac) {
        delete ctrls[channel];
        document.querySelectorAll(`[data-channel="${channel}"]`).forEach((e) => e.classList.remove("busy"));
      }
    }
  }

  const num = (t) => { const x = Number(String(t).trim()); return isFinite(x) && String(t).trim() !== "" ? x : null; };
  // the model's own names in a library message that gave no option ("delay_samples = ...")
  const MODEL_NAMES = { delay_samples: "delay", period_s: "period", delay_s: "delay-s",
                        delay_forward_samples: "delay-forward", delay_backward_samples: "delay-backward" };
  function fieldFor(param, message) {
    if (!param && message) {
      const m = /^([a-z_]+) = /.exec(message);
      param = m && MODEL_NAMES[m[1]];
    }
    if (!param) return null;
    let n = String(param).replace(/_/g, "-");
    if (n === "K") n = "_kwin"; else if (n === "B") n = "_bwin";
    n = ALT_OF[n] || n;
    return $(`#form .field[data-name="${n}"]`);
  }

  function clearErrors() {
    document.querySelectorAll("#form .field.invalid").forEach((f) => { f.classList.remove("invalid"); $(".msg", f).textContent = ""; });
    $("#form-error").textContent = "";
  }
  function showError(res, where) {
    const f = fieldFor(res.parameter, res.error);
    if (f) {
      if (!f.classList.contains("invalid")) { f.classList.add("invalid"); $(".msg", f).textContent = res.error; }
      if (f.closest("details")) f.closest("details").open = true;
      return true;
    }
    if (where) where(res.error);
    else if (!$("#form-error").textContent) $("#form-error").textContent = res.error;
    return false;
  }
  const stale = (channel, on) => document.querySelectorAll(`[data-channel="${channel}"]`).forEach((e) => e.classList.toggle("stale", on));

  // a card's answer replaced by one line (a refusal, or "not available for this model")
  function cardNote(command, text) {
    if (command === "kmax") { setNum("#kmax", null); $("#kmax-detail").textContent = text; $("#kmax-detail").title = text; }
    else if (command === "check") {
      const v = $("#verdict"); v.textContent = "–"; v.dataset.value = ""; v.className = "big";
      $("#verdict-detail").textContent = text; $("#verdict-detail").title = text;
    } else if (command === "audit") { setNum("#passivity-kmax", null); $("#paper-rows").textContent = text; }
  }
  // the answer of COMMAND is this one line: on its plot (or card), nothing else drawn
  function refused(command, channel, plot, text) {
    delete shown[command];
    stale(channel, false);
    if (plot) HapstabPlots.note(plot, text); else cardNote(command, text);
    if (command === "passivity") $("#passivity-detail").textContent = "at K: " + text;
  }

  // MODEL commands refuse what the model refuses: their errors mark the input fields; any
  // other command's refusal of a valid model is that command's, shown on its plot or card
  const MODEL = ["kmax", "check"];
  async function update() {
    const seq = ++SEQ;
    writeUrl();
    netAbortChanged();        // a network question that changed frees its worker at once
    const errors = [], notes = [];
    const run = async (channel, command, extra, draw, plot) => {
      const na = unavailable(command);
      if (na) { if (seq === SEQ) { refused(command, channel, plot, na); notes.push(na); } return null; }
      const res = await call(channel, command, optionsFor(command, extra), seq);
      if (res.superseded) return null;
      if (res.error) { errors.push(Object.assign(res, { command, channel, plot })); stale(channel, true); return null; }
      shown[command] = res.ok;
      stale(channel, false);
      try { draw(res.ok); } catch (e) { console.error(e); HapstabPlots.note(plot || "boundary", `cannot draw: ${e.message}`); }
      return res.ok;
    };
    const cur = current();
    const kmaxP = run("kmax", "kmax", {}, drawKmax);
    const checkP = run("check", "check", {}, drawCheck);
    // the margins (seconds for a PEB) in a request of their own on the "margins" channel:
    // the verdict does not wait for them, and a later change supersedes them
    $("#margins-detail").textContent = "";
    if (!unavailable("check")) {
      call("margins", "check", optionsFor("check", { margins: true, "margin-seconds": MARGIN_SECONDS }), seq).then((r) => {
        if (r.ok) drawMargins(r.ok);
        else if (!r.superseded) $("#margins-detail").textContent = "margins: " + r.error;
      });
    }
    const auditP = run("audit", "audit", {}, drawAudit);
    const simP = run("simulate", "simulate", simExtra(), (a) => HapstabPlots.simulate(a), "simulate");
    const pasP = run("passivity", "passivity", has("passivity", "curve") ? { curve: CURVE_POINTS } : {},
                     (a) => { drawPassivity(a); HapstabPlots.passivity(a); }, "passivity");
    // the best damping, for the K-B window only (its refusal refuses nothing the page shows)
    const bestP = unavailable("best-damping") ? Promise.resolve(null)
      : call("best-damping", "best-damping", optionsFor("best-damping", {}), seq).then((r) => {
        if (r.ok) shown["best-damping"] = r.ok; else if (!r.superseded) delete shown["best-damping"];
        return r.ok || null;
      });
    const km = await kmaxP;
    const check = await checkP;
    cur.kmax = km ? km.critical_stiffness : null;
    cur.verdict = check ? check.verdict : null;
    if (km) {    // the plots around the current T: the T the CLI read (a unit, a rate...)
      cur.period_s = km.period_s;
      const best = await bestP;
      if (seq !== SEQ) return;
      await Promise.all([
        run("region", "region", regionExtra(km, cur, best), (a) => HapstabPlots.region(a, cur), "region"),
        run("boundary", "boundary", boundaryExtra(km.period_s),
            (a) => HapstabPlots.boundary(a, cur), "boundary"),
      ]);
    } else { stale("boundary", true); stale("region", true); }
    await Promise.all([auditP, simP, pasP]);
    if (seq !== SEQ) return;
    clearErrors();
    const model = errors.filter((e) => MODEL.includes(e.command));
    for (const e of model) showError(e);
    const own = model.length ? [] : errors;    // a valid model: each refusal is its command's
    for (const e of own) refused(e.command, e.channel, e.plot, e.error);
    const s = $("#status");
    if (model.length) { s.className = "error"; s.textContent = "input refused"; }
    else if (own.length) { s.className = "error"; s.textContent = "refused: " + [...new Set(own.map((e) => e.command))].join(", "); }
    else if (!inflight) { s.className = "idle"; s.textContent = notes.length ? "up to date (some plots not available)" : "up to date"; }
    modelRefused = model.length > 0;
    network();                // after every main answer: it never holds back the verdict
    document.body.dataset.seq = String(seq);
    document.body.dataset.settled = model.length ? "error" : own.length ? "refused" : "ok";
    updating = false;
    delete document.body.dataset.pending;
  }

  function current() {
    const K = num(value("stiffness")), B = num(value("virtual-damping"));
    // a delay typed with its unit (10ms) keeps it; a plain number is seconds
    const ds = state.values["delay-s"] != null ? String(value("delay-s")).trim() : null;
    const delay = ds != null ? (/[a-zµμ]$/i.test(ds) ? ds : ds + " s") : `${value("delay") || 0} samples`;
    return { stiffness: K, B: B == null ? 0 : B, delayLabel: delay, rateMode: "rate" in state.values };
  }

  function simExtra() {
    const o = optsOf("simulate").find((x) => x.name === "series");
    if (!o) return {};
    return { series: o.type === "flag" ? true : 1000 };
  }

  // periods (or rates) T/4 ... 4T around the current T (the kmax answer's period_s, as the
  // CLI read the field), log-spaced, the current one included at full precision
  function boundaryExtra(period_s) {
    if (!(period_s > 0)) return {};
    const rateMode = "rate" in state.values;
    const centre = rateMode ? 1 / period_s : period_s;
    const xs = [];
    for (let i = 0; i < SWEEP; i++) xs.push(String(+(centre * Math.pow(16, i / (SWEEP - 1)) / 4).toPrecision(10)));
    xs[(SWEEP - 1) / 2] = String(centre);
    const extra = rateMode ? { rate: xs.join(",") } : { period: xs.join(",") };
    if ("delay-s" in state.values) extra["delay-s"] = value("delay-s");
    else extra.delay = value("delay") === "" ? 0 : jsonValue({ type: "float" }, value("delay"));
    return extra;
  }

  // the K-B window (window.js): around the device's damping b (PEB: the smaller of the
  // two) and, when the best damping is known, following it (B* and every stable B inside)
  function regionExtra(km, cur, best) {
    const kw = (state.values._kwin || "").trim(), bw = (state.values._bwin || "").trim();
    const b = state.kind === "hve" ? num(value("damping"))
      : Math.min(num(value("master-damping")) ?? Infinity, num(value("slave-damping")) ?? Infinity);
    const win = HapstabWindow.kbWindow({ kmax: km.critical_stiffness, K: cur.stiffness, B: cur.B, b,
                                         best: best || null });
    const out = { K: kw || win.K, B: bw || win.B, resolution: REGION_RESOLUTION };
    if (has("region", "overlay")) out.overlay = "none";     // drawn by the CLI's --plot only
    return out;
  }

  // ------------------------------------------------------------------ the cards
  const fmt = (v, p = 6) => (v == null ? "–" : Math.abs(v) >= 1e6 || (v !== 0 && Math.abs(v) < 1e-4) ? v.toExponential(p - 1) : String(+v.toPrecision(p)));
  function setNum(id, v) { const e = $(id); e.dataset.value = v == null ? "" : String(v); e.textContent = fmt(v); }

  function drawKmax(a) {
    setNum("#kmax", a.critical_stiffness);
    const f = a.crossing_frequency_hz;
    $("#kmax-detail").textContent = (f != null ? `crossing at ${fmt(f, 4)} Hz · ` : "") + a.reason;
    $("#kmax-detail").title = a.reason;
  }
  function drawCheck(a) {
    const v = $("#verdict");
    v.textContent = a.verdict;
    v.dataset.value = a.verdict; v.className = "big " + a.verdict;
    $("#verdict-detail").textContent = (a.stiffness != null ? `at K = ${fmt(a.stiffness)} N/m · ` : "") +
      `spectral radius ${fmt(a.spectral_radius, 8)}` +
      (a.frequency_hz != null ? ` · ${fmt(a.frequency_hz, 4)} Hz` : "") +
      " · " + a.reason;
    $("#verdict-detail").title = a.reason;
  }
  // the margins' answer (a check with "margins": true), when it arrives
  function drawMargins(a) {
    const parts = [];
    if (a.delay_margin_s != null) parts.push(`delay margin ${fmt(a.delay_margin_s * 1e3, 4)} ms` +
      (a.delay_unstable_s == null ? " (no loss in the search)" : ""));
    if (a.stiffness_max_N_per_m != null) parts.push(`stable K up to ${fmt(a.stiffness_max_N_per_m)} N/m`);
    const why = a.margins_reason || "";
    $("#margins-detail").textContent = parts.length ? parts.join(" · ") : why;
    $("#margins-detail").title = why;
  }
  function drawAudit(a) {
    setNum("#passivity-kmax", a.passivity_kmax);
    const rows = a.rows.filter((r) => CLOSED.includes(r.key));
    const box = $("#paper-rows");
    box.replaceChildren();
    if (!rows.length) box.textContent = "none of the paper's closed forms applies to this loop";
    for (const r of rows) {
      const d = document.createElement("div"); d.className = "row"; d.dataset.key = r.key;
      const k = document.createElement("span"); k.className = "k"; k.dataset.value = String(r.critical_stiffness);
      k.textContent = r.critical_stiffness == null ? "∞" : fmt(r.critical_stiffness) + " N/m";
      const l = document.createElement("span"); l.className = "l"; l.textContent = r.label; l.title = r.note;
      d.append(k, l); box.appendChild(d);
      if (r.flag) { const fl = document.createElement("div"); fl.className = "flag"; fl.textContent = "⚠ " + r.flag; fl.title = r.flag; box.appendChild(fl); }
    }
    const others = (a.flagged || []).filter((k) => !CLOSED.includes(k));
    if (others.length) { const d = document.createElement("div"); d.className = "flag"; d.textContent = "also flagged: " + others.join(", "); box.appendChild(d); }
  }
  function drawPassivity(a) {
    const p = $("#passivity-detail");
    p.textContent = `at K: ${a.verdict}, margin ${fmt(a.margin, 4)} N·s/m at ${fmt(a.worst_frequency_hz, 4)} Hz`;
    p.title = a.reason;
  }

  // ------------------------------------------------------------------ the network card
  // Each of its three questions is asked once per distinct request: a change elsewhere
  // (K, the plots' window) that leaves it the same keeps its answer, or its flight.
  const netKey = {};            // channel -> the request its answer or flight is for
  let modelRefused = false, netTimer = null;

  function netRequests() {
    const out = {};
    for (const [ch, r] of Object.entries(NET.requests(state.values))) {
      if (r.hint) { out[ch] = r; continue; }
      const na = unavailable(r.command, r.drop);
      if (na) { out[ch] = { error: na }; continue; }
      const options = optionsFor(r.command, {});
      for (const d of r.drop) delete options[d];
      out[ch] = { command: r.command, options: Object.assign(options, r.extra),
                  key: JSON.stringify([state.kind, r.command, options]) };
    }
    return out;
  }
  // before the main answers are asked: a network request whose question changed is
  // aborted (the server ends its worker), so that it never holds a worker they wait for
  function netAbortChanged() {
    const reqs = netRequests();
    for (const ch of NET.CHANNELS) {
      if (ctrls[ch] && netKey[ch] !== reqs[ch].key) { netKey[ch] = null; ctrls[ch].abort(); }
    }
  }
  function netShow(ch, a, hint, error) {
    const el = $("#" + ch);
    el.classList.remove("stale");
    el.classList.toggle("hinted", !a && !error);
    const r = a ? NET.read[ch](a, shown.kmax ? shown.kmax.critical_stiffness : null) : null;
    const v = $(`#${ch}-value`);
    v.textContent = r ? r.big : "–";
    v.dataset.value = r ? JSON.stringify(r.values) : "";
    const lines = { detail: r ? r.detail : hint || "", model: r ? r.model : "", cmp: r ? r.cmp : "",
                    msg: error || "" };
    for (const [k, text] of Object.entries(lines)) { const e = $(`#${ch}-${k}`); e.textContent = text; e.title = text; }
    if (a) shown[ch] = a; else delete shown[ch];
  }
  function network() {
    const reqs = netRequests();
    for (const ch of NET.CHANNELS) {
      const r = reqs[ch];
      if (modelRefused) { stale(ch, true); continue; }     // the loop's fields say why
      if (!r.key) {
        netKey[ch] = null;
        if (ctrls[ch]) ctrls[ch].abort();
        netShow(ch, null, r.hint, r.error);
        continue;
      }
      if (netKey[ch] === r.key) {                         // the same question
        if (!ctrls[ch] && shown[ch]) netShow(ch, shown[ch]);   // (the page's K_max may be new)
        if (ctrls[ch] || shown[ch] || $(`#${ch}-msg`).textContent) continue;
      }
      const key = netKey[ch] = r.key;
      call(ch, r.command, r.options, ++NETSEQ, () => netKey[ch] === key).then((res) => {
        if (res.superseded) return;
        if (res.error) netShow(ch, null, null, res.error); else netShow(ch, res.ok);
      });
    }
  }
  // a change of the card's own inputs asks the card only (the loop's answers stand)
  function scheduleNet() {
    if (updating) return;            // update() asks the card at its end, with these values
    clearTimeout(netTimer);
    document.body.dataset.pending = "1";
    netTimer = setTimeout(() => {
      writeUrl();
      if (!updating) { network(); delete document.body.dataset.pending; }
    }, DEBOUNCE_MS);
  }

  // ------------------------------------------------------------------ downloads, code
  function download(name, data, type) {
    const a = document.createElement("a");
    a.href = data.startsWith("data:") ? data : URL.createObjectURL(new Blob([data], { type }));
    a.download = name;
    document.body.appendChild(a); a.click(); a.remove();
  }
  async function copyCode(which) {
    const command = $("#code-command").value;
    const box = $("#code");
    try {
      const r = await fetch(API + "code", { method: "POST", headers: { "Content-Type": "application/json" },
        body: JSON.stringify({ kind: state.kind, command, options: optionsFor(command, extraFor(command)) }) });
      const body = await r.json();
      if (!r.ok) { box.value = "error: " + body.error; return; }
      box.value = body[which];
      box.dataset.which = which;
      try { await navigator.clipboard.writeText(body[which]); $("#status").textContent = "copied"; } catch (e) { /* not allowed here: the box shows it */ }
    } catch (e) { box.value = "error: " + e.message; }
  }
  function extraFor(command) {
    if (command === "boundary") return shown.kmax ? boundaryExtra(shown.kmax.period_s) : {};
    if (command === "region" && shown.kmax) return regionExtra(shown.kmax, current(), shown["best-damping"]);
    if (command === "passivity") return {};
    return {};
  }

  function wire() {
    document.querySelectorAll('#kind input[name="kind"]').forEach((r) => r.addEventListener("change", () => setKind(r.value)));
    $("#copy-cli").onclick = () => copyCode("cli");
    $("#copy-python").onclick = () => copyCode("python");
    $("#copy-link").onclick = async () => { try { await navigator.clipboard.writeText(location.href); $("#status").textContent = "link copied"; } catch (e) { $("#code").value = location.href; } };
    $("#download-json").onclick = () => download("hapstab-explorer.json",
      JSON.stringify({ kind: state.kind, options: state.values, url: location.href, answers: shown }, null, 1), "application/json");
    document.querySelectorAll("[data-csv]").forEach((b) => (b.onclick = () => {
      const t = HapstabPlots.csv(b.dataset.csv); if (t) download(`hapstab-${b.dataset.csv}.csv`, t, "text/csv"); }));
    document.querySelectorAll("[data-png]").forEach((b) => (b.onclick = () => {
      const u = HapstabPlots.png(b.dataset.png); if (u) download(`hapstab-${b.dataset.png}.png`, u); }));
    let rt = null;
    window.addEventListener("resize", () => { clearTimeout(rt); rt = setTimeout(HapstabPlots.resize, 100); });
  }

  async function start() {
    wire();
    try {
      const r = await fetch(API + "schema");
      if (!r.ok) throw new Error(`HTTP ${r.status}`);
      schema = await r.json();
    } catch (e) {
      const f = $("#fatal"); f.hidden = false;
      f.textContent = `The explorer's server did not give its schema (${e.message}); start it with: hapstab explore`;
      return;
    }
    readUrl();
    $(`#kind input[value="${state.kind}"]`).checked = true;
    buildForm();
    // a value the URL (or the study) sets in "More options" is shown, not hidden
    if (Object.keys(state.values).some((k) => $(`#more-fields .field[data-name="${ALT_OF[k] || k}"], #view-fields .field[data-name="${k}"]`)))
      $("#more").open = true;
    update();
  }
  window.HapstabExplorer = { state, shown, optionsFor };
  start();
})();

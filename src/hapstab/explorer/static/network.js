/* hapstab explorer: the network card (issue 30 item 5) — which requests its inputs make,
 * and how each answer reads.
 *
 * Three questions about the loop on the page, each one request to the API the CLI answers:
 *   delay range  POST kmax   {"delay-range": "5ms:15ms"}   the certified minimum K_max
 *                (seconds: the delay acts between the samples, proved over the continuum)
 *   jitter       POST jitter {"delay": "5:15"}             the bracket [stable_up_to, unstable_from]
 *   loss         POST kmax   {"loss": P, "burst": L}       the mean-square K_max
 * The range and the jitter replace the loop's one constant delay (its delay options are
 * not sent); the loss keeps it. Each answer is compared with the constant-delay K_max
 * (the page's kmax answer). Pure and without the page: app.js draws what these return.
 */
"use strict";

const HapstabNetwork = (() => {
  // the card's inputs: page fields (in the URL, never sent as loop options)
  const FIELDS = ["_range", "_jitter", "_loss", "_burst"];
  const CHANNELS = ["net-range", "net-jitter", "net-loss"];
  // the loop's delay options, replaced by a range
  const DELAYS = ["delay", "delay-s", "delay-forward", "delay-backward"];

  const fmt = (v, p = 6) => (v == null ? "–" : Math.abs(v) >= 1e6 || (v !== 0 && Math.abs(v) < 1e-4)
    ? v.toExponential(p - 1) : String(+v.toPrecision(p)));

  // values: the page's field texts. Returns channel -> {command, extra, drop} (a request:
  // the loop's options without `drop`, with `extra`) or {hint} (nothing to ask yet)
  function requests(values) {
    const t = (k) => String(values[k] == null ? "" : values[k]).trim();
    const out = {};
    out["net-range"] = t("_range")
      ? { command: "kmax", extra: { "delay-range": t("_range") }, drop: DELAYS }
      : { hint: "give the range the constant delay lies in: 5ms:15ms (seconds, with a unit) or 5:15 (samples)" };
    out["net-jitter"] = t("_jitter")
      ? { command: "jitter", extra: { delay: t("_jitter") }, drop: DELAYS }
      : { hint: "give the range the delay varies in from sample to sample: 5:15 (samples) or 5ms:15ms" };
    if (t("_loss")) {
      const extra = { loss: t("_loss") };
      if (t("_burst")) extra.burst = t("_burst");
      out["net-loss"] = { command: "kmax", extra, drop: [] };
    } else {
      out["net-loss"] = { hint: t("_burst") ? "give the loss probability P that the bursts make up"
        : "give a loss probability P (0.02: 2 % of the packets), and a mean burst length L if losses come in bursts" };
    }
    return out;
  }

  // "0.678 × the constant-delay K_max (9.5361 N/m)"
  function compared(v, ref, what = "the constant-delay K_max") {
    if (!(ref > 0) || v == null || !isFinite(v)) return "";
    return `${fmt(v / ref, 3)} × ${what} (${fmt(ref)} N/m)`;
  }

  // each reading: {values: {name: number}, big, detail, model, cmp}; ref: the page's K_max
  // (the constant delay of the page's loop)
  function range(a, ref) {
    const d = a.delays_samples || [];
    const s = a.delay_range_s ? `${fmt(a.delay_range_s[0] * 1e3, 4)}–${fmt(a.delay_range_s[1] * 1e3, 4)} ms`
      : "the range";
    // a range in seconds: the delay acts between the samples, proved over the continuum
    const between = a.fractional === true;
    return {
      values: { kmax: a.critical_stiffness, worst: a.worst_delay_samples },
      big: fmt(a.critical_stiffness),
      detail: between
        ? `worst delay ${fmt(a.worst_delay_s * 1e3, 4)} ms · minimum in [${fmt(a.critical_stiffness)}, ` +
          `${fmt(a.upper_bound_N_per_m)}] N/m`
        : `worst delay ${fmt(a.worst_delay_samples)} samples${a.round_trip ? " (round trip)" : ""}` +
          (d.length ? ` of ${fmt(d[0])}…${fmt(d[d.length - 1])}` : ""),
      model: (a.certified ? "exact: the certified minimum"
        : between ? "exact: a proved lower end, uncertain above it" : "exact criterion, not certified") +
        (between ? ` · one constant delay, unknown in ${s}${a.same_delay_both_ways ? " (the same one-way delay both ways)" : ""}, acting between the samples (every delay of the continuum)`
          : ` · one constant delay, unknown in ${s}, used from the next sampling instant`),
      cmp: compared(a.critical_stiffness, ref),
    };
  }

  function pattern(steps) {
    return (steps || []).map((s) => (s.length > 1 ? `(${s.join(",")})` : String(s[0]))).join(" ");
  }

  function jitter(a, ref) {
    const up = a.stable_up_to_N_per_m, from = a.unstable_from_N_per_m;
    const pct = a.relative_gap == null ? "" : `, ${fmt(a.relative_gap * 100, 2)} %`;
    const r = a.delay_range_samples || [];
    const worst = a.constant_delay_worst_N_per_m;
    return {
      values: { stable: up, unstable: from, gap: a.gap_N_per_m },
      big: `${fmt(up)} … ${fmt(from)}`,
      detail: (from == null ? "no destabilising pattern found" :
        `destabilising pattern ${pattern(a.pattern_samples)}${a.pattern_is_constant ? " (constant)" : " (repeated)"}`) +
          ` · gap ${fmt(a.gap_N_per_m, 4)} N/m${pct}`,
      model: "stable up to: sufficient (small gain); unstable from: exact for its pattern · each " +
        `sample's delay anywhere in ${r.length ? r.join("…") + " samples" : "the range"}, the newest arrival used`,
      cmp: compared(up, ref, "the constant-delay K_max") +
        (worst != null ? `; the worst constant delay of the range: ${fmt(worst)} N/m` : ""),
    };
  }

  function loss(a, ref) {
    const how = a.burst_samples != null ? `in bursts of mean ${fmt(a.burst_samples, 4)} (Gilbert–Elliott)`
      : "independently";
    const model = (what) => `mean-square: ${what} · packets lost with probability P, ${how}, the last value held`;
    if (Array.isArray(a.critical_stiffness)) {          // a range of P: K_max against P
      const ks = a.critical_stiffness;
      return {
        values: { kmax: Math.min(...ks) },
        big: `${fmt(Math.min(...ks))} … ${fmt(Math.max(...ks))}`,
        detail: (a.losses || []).map((p, i) => `P ${fmt(p, 4)}: ${fmt(ks[i])}`).join(" · "),
        model: model("exact criterion, floating point"),
        cmp: "at the first P: " + compared(ks[0], ref),
      };
    }
    return {
      values: { kmax: a.critical_stiffness, upper: a.upper_bound },
      big: fmt(a.critical_stiffness),
      detail: `unstable from ${fmt(a.upper_bound, 10)} N/m` +
        (a.networked_terms ? ` · lost: ${a.networked_terms.join(", ")}` : ""),
      model: model(a.certified ? "exact, certified (no loss)" : "exact criterion, floating point"),
      cmp: compared(a.critical_stiffness, a.loss_free_critical_stiffness ?? ref, "the K_max without loss"),
    };
  }

  const read = { "net-range": range, "net-jitter": jitter, "net-loss": loss };
  return { FIELDS, CHANNELS, DELAYS, requests, read, pattern };
})();

if (typeof module !== "undefined") module.exports = HapstabNetwork;   // node (tests)

/* hapstab explorer: the K–B window of the region plot, from the answers it must show.
 *
 * Without an answer to follow, B spans -b/4 ... 4b (b the device's damping; or 2|B|) and K
 * up to where the closed forms' K_max (b + B)/(T/2 + t_d) would be at the top B. But K_max
 * over B usually peaks far beyond 4b (a 0.8 N·s/m device with 10 ms of delay at 2 kHz:
 * B* = 22 N·s/m, K* = 1320 N/m), and a window at B <= 3 hides the answer. So when the
 * best damping is known (the explorer asks hapstab best-damping, which searches B until
 * K_max falls back to 0 on both sides), the window follows it: B covers every damping with
 * a stable K (the best-damping curve's K > 0) and B* with a margin, and K goes up to 1.2 K*
 * (K* is the largest K_max over every B searched, so the whole stable region fits).
 * Pure and without the page: tests/explorer/test_explorer_window.py runs it under node.
 */
"use strict";

const HapstabWindow = (() => {
  const round = (v) => +v.toPrecision(4);

  // o: {kmax, K, B, b, best}; best: the best-damping answer (or null). Returns {K, B} as
  // "lo:hi" strings, the region command's --K and --B.
  function kbWindow(o) {
    const K = o.K || 0, B = o.B || 0, kmax = o.kmax || 0;
    const b = o.b > 0 && isFinite(o.b) ? o.b : 0.1;
    let bHi = Math.max(2 * Math.abs(B), 4 * b);
    let bLo = Math.min(-0.25 * b, 2 * B);
    let kHi = Math.max(1.2 * kmax * (b + bHi) / b, 1.5 * K, 1);
    const best = o.best;
    if (best && isFinite(best.virtual_damping) && best.critical_stiffness > 0) {
      const Bs = best.virtual_damping;
      let lo = Math.min(Bs, 0), hi = Math.max(Bs, 0);
      const c = best.curve || {};
      (c.virtual_damping || []).forEach((x, i) => {
        if (c.critical_stiffness[i] > 0) { lo = Math.min(lo, x); hi = Math.max(hi, x); }
      });
      const span = Math.max(hi - lo, Math.abs(Bs), b);
      bHi = Math.max(2 * Math.abs(B), hi + 0.1 * span);            // the stable B, and a margin
      bLo = Math.min(2 * B, lo - 0.1 * span, -0.25 * b);
      kHi = Math.max(1.2 * best.critical_stiffness, 1.5 * K, 1.2 * kmax, 1);
    }
    return { K: `0:${round(kHi)}`, B: `${round(bLo)}:${round(bHi)}` };
  }

  return { kbWindow };
})();

if (typeof module !== "undefined" && module.exports) module.exports = HapstabWindow;

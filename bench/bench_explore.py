"""Latency of the explorer's tiers (`maglev-match explore`), against the same API calls
made directly in the same process as the baseline.

* slider moves: ``--moves`` (50) requests ``/api/quick`` along a sweep of kD (each waits
  for its answer: the time from the input to the data the page redraws from), baseline
  ``api.stability`` at the same designs;
* releases: ``--releases`` (20) requests ``/api/release`` at neighbouring designs (kD
  stepped 1 % each time, as a slider let go near where it was), warm-started from the
  previous release; baseline ``api.matching_index(..., near=previous)`` on the same
  sequence of designs (shifted by half a step, so that neither side reuses the other's
  answer);

each without a delay (tau = 0) and with one (``--tau 0,1e-3``, the default: both).
With ``--background N`` (tau = 0): the background tiers' time from the start of a job to
its result (the map tile, the speed sweep to 60 km/h, the cycle branch; one warm-up job
each in the child, then N jobs at designs kD stepped 1 %); baseline the same job function
called directly in this process. With ``--browser N``: the interpolated-chi slider tier
in the page (headless Chromium): N moves of the EI slider inside the map tile, each the
time from the input event to the redrawn, interpolated chi (one request ``/api/quick``
and the page's interpolation and drawing); no baseline (a page-only path).
Medians and 95th percentiles (nearest rank); the server's time includes HTTP, JSON and,
for a release, the cycle curve and the critical run the page draws. Not the browser's drawing time.

    PYTHONPATH=src python bench/bench_explore.py [--moves 50] [--releases 20] [--tau 0,1e-3]
        [--background 3] [--browser 50]
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import time
import urllib.request


def pct(values: list[float], q: float) -> float:
    """The q-th percentile, nearest rank."""
    s = sorted(values)
    return s[max(0, math.ceil(q / 100 * len(s)) - 1)]


def row(name: str, server: list[float], direct: list[float]) -> dict:
    out = {"tier": name, "n": len(server),
           "server_median_s": statistics.median(server), "server_p95_s": pct(server, 95),
           "direct_median_s": statistics.median(direct), "direct_p95_s": pct(direct, 95)}
    out["ratio_median"] = out["server_median_s"] / out["direct_median_s"]
    return out


def browser_moves(base: str, preset: str, n: int) -> dict:
    """The interpolated-chi tier in the page: n moves of the EI slider inside the map tile
    (the tile computed first), each from the input event to the redrawn chi."""
    from playwright.sync_api import sync_playwright

    args = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run"]
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path="/usr/bin/chromium", args=args)
        page = b.new_page(viewport={"width": 1500, "height": 1000})
        page.goto(f"{base}/?preset={preset}&EI=2.2e10&kD=140")
        page.wait_for_function("() => document.getElementById('tile-status').dataset.status"
                               " === 'done'", timeout=900_000)
        times = []
        for k in range(n):
            step = 510 + (k % 20)  # EI within +-10 % of 2.2e10: inside the tile
            times.append(page.evaluate("""async (k) => {
                const t0 = performance.now(), before = S.seq;
                const el = document.getElementById('slider-EI');
                el.value = String(k); el.dispatchEvent(new Event('input'));
                while (S.shown.quick <= before) await new Promise((r) => setTimeout(r, 0));
                if (document.getElementById('chi-interp').dataset.state !== 'interpolated')
                    throw new Error('not interpolated');
                return performance.now() - t0; }""", step) / 1e3)
        b.close()
    return {"tier": "slider move, chi interpolated (browser)", "n": n,
            "server_median_s": statistics.median(times), "server_p95_s": pct(times, 95),
            "direct_median_s": math.nan, "direct_p95_s": math.nan, "ratio_median": math.nan}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--moves", type=int, default=50)
    ap.add_argument("--releases", type=int, default=20)
    ap.add_argument("--tau", default="0,1e-3",
                    help="the delays, comma-separated (s; 0: without a delay)")
    ap.add_argument("--preset", default="turnout-soft")
    ap.add_argument("--background", type=int, default=0,
                    help="jobs per background tier (0: not measured)")
    ap.add_argument("--browser", type=int, default=0,
                    help="moves of the interpolated-chi tier in the browser (0: not measured)")
    args = ap.parse_args()

    from maglev_match import api
    from maglev_match.explore.server import ExploreServer

    server = ExploreServer(args.preset, "unit", port=0).start()
    base = f"http://127.0.0.1:{server.port}"
    seq = [0]

    def get(path: str) -> float:
        seq[0] += 1
        t = time.perf_counter()
        with urllib.request.urlopen(f"{base}{path}&seq={seq[0]}", timeout=600) as r:
            body = json.loads(r.read())
        dt = time.perf_counter() - t
        if "error" in body or "errors" in body or body.get("stale"):
            raise RuntimeError(body)
        return dt

    def timed(fn) -> float:
        t = time.perf_counter()
        fn()
        return time.perf_counter() - t

    def post(path: str) -> dict:
        seq[0] += 1
        req = urllib.request.Request(f"{base}{path}&seq={seq[0]}", method="POST")
        with urllib.request.urlopen(req, timeout=600) as r:
            return json.loads(r.read())

    def job_time(kind: str, kd: float) -> float:
        t = time.perf_counter()
        job = post(f"/api/job?kind={kind}&preset={args.preset}&kD={kd!r}&v=60")
        while job["status"] in ("queued", "running"):
            time.sleep(0.05)
            with urllib.request.urlopen(f"{base}/api/job/{job['id']}", timeout=600) as r:
                job = json.loads(r.read())
        if job["status"] != "done":
            raise RuntimeError(job)
        return time.perf_counter() - t

    rows = []
    load_before = open("/proc/loadavg").read().split()[:3]
    for tau in (float(t) for t in args.tau.split(",")):
        extra = {} if tau == 0 else {"tau": tau}
        q = "".join(f"&{k}={v!r}" for k, v in extra.items())
        # warm-up: compile every kernel of both paths once (not measured)
        get(f"/api/quick?preset={args.preset}{q}")
        get(f"/api/release?preset={args.preset}{q}")
        api.stability(args.preset, **extra)
        prev = api.matching_index(args.preset, stage=False, **extra)
        kd0 = 150.0
        moves = [kd0 * (0.8 + 0.4 * k / max(1, args.moves - 1)) for k in range(args.moves)]
        s_quick = [get(f"/api/quick?preset={args.preset}&kD={kd!r}{q}") for kd in moves]
        d_quick = [timed(lambda kd=kd, extra=extra: api.stability(args.preset, kD=kd,
                                                                  **extra))
                   for kd in moves]
        rel = [kd0 * 1.01 ** k for k in range(1, args.releases + 1)]
        s_rel = [get(f"/api/release?preset={args.preset}&kD={kd!r}{q}") for kd in rel]
        d_rel = []
        for kd in rel:
            t = time.perf_counter()
            prev = api.matching_index(args.preset, stage=False, near=prev,
                                      kD=kd * 1.005, **extra)
            d_rel.append(time.perf_counter() - t)
        label = "tau = 0" if tau == 0 else f"tau = {tau:g} s"
        rows.append(row(f"slider move ({label})", s_quick, d_quick))
        rows.append(row(f"release ({label})", s_rel, d_rel))
        print(json.dumps(rows[-2:]), flush=True)  # each delay's rows as they finish
    if args.background:
        from maglev_match.core.params import load_params
        from maglev_match.explore.background import KINDS

        for kind, extra in (("tile", {}), ("speed", {"v": 60.0}), ("cycle_branch", {})):
            job_time(kind, 150.0)  # warm-up: the child compiles this kind's kernels
            KINDS[kind](load_params(args.preset, None, {"kD": 150.0}), "unit",
                        lambda _: None, **extra)
            kds = [150.0 * 1.01 ** k for k in range(1, args.background + 1)]
            s_bg = [job_time(kind, kd) for kd in kds]
            d_bg = [timed(lambda kd=kd, kind=kind, extra=extra: KINDS[kind](
                load_params(args.preset, None, {"kD": kd * 1.005}), "unit", lambda _: None,
                **extra)) for kd in kds]
            rows.append(row(f"background: {kind} (tau = 0)", s_bg, d_bg))
            print(json.dumps(rows[-1]), flush=True)
    if args.browser:
        rows.append(browser_moves(base, args.preset, args.browser))
        print(json.dumps(rows[-1]), flush=True)
    server.stop()
    load_after = open("/proc/loadavg").read().split()[:3]
    print(f"load average before: {' '.join(load_before)}; after: {' '.join(load_after)}")
    print(f"{'tier':28s} {'n':>3s} {'median':>9s} {'p95':>9s} {'direct med':>11s} "
          f"{'direct p95':>11s} {'ratio':>6s}")
    for r in rows:
        print(f"{r['tier']:28s} {r['n']:3d} {r['server_median_s'] * 1e3:7.1f}ms "
              f"{r['server_p95_s'] * 1e3:7.1f}ms {r['direct_median_s'] * 1e3:9.1f}ms "
              f"{r['direct_p95_s'] * 1e3:9.1f}ms {r['ratio_median']:6.2f}")
    print(json.dumps({"load_before": load_before, "load_after": load_after, "rows": rows}))


if __name__ == "__main__":
    main()

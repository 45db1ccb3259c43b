#!/usr/bin/env python3
"""Look at `measure --live` in a real browser (headless Chromium), as CI does when it can.

Starts a simulated stepper bench and a measurement with `--live` on it, lets Chromium load
the page while the run goes, and checks what its script made of it: the run's name, the
figures filled in, no script error in the console. Saves a screenshot (for a person to look
at), then presses Stop the way the page does (POST /stop) and checks the run ends cancelled
with exit code 130.

Usage: scripts/live-view-check.py BIN CHROMIUM OUT_DIR
  BIN       the mpc-rig binary (target/debug/mpc-rig or target/release/mpc-rig)
  CHROMIUM  the browser (chromium)
  OUT_DIR   where the recording, the screenshot and the logs go (emptied first)
Exit status 0 when every check holds; otherwise 1, with what failed.
"""

import html.parser
import json
import os
import shutil
import subprocess
import sys
import time
import urllib.request

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MOTION = os.path.join(REPO, "data/motions/half-turn-2to1.toml")
RIG = os.path.join(REPO, "rigs/sim-stepper.toml")


class Figures(html.parser.HTMLParser):
    """The text of the elements with an id, from the DOM Chromium dumps."""

    def __init__(self):
        super().__init__()
        self.text = {}
        self._open = []

    def handle_starttag(self, tag, attrs):
        self._open.append(dict(attrs).get("id"))

    def handle_endtag(self, tag):
        if self._open:
            self._open.pop()

    def handle_data(self, data):
        if self._open and self._open[-1]:
            key = self._open[-1]
            self.text[key] = self.text.get(key, "") + data


def fail(message):
    print(f"FAIL: {message}")
    sys.exit(1)


def state(url, since=0):
    with urllib.request.urlopen(f"{url}state?since={since}", timeout=5) as r:
        return json.load(r)


def main():
    if len(sys.argv) != 4:
        print(__doc__)
        sys.exit(2)
    binary, chromium, out = sys.argv[1:]
    shutil.rmtree(out, ignore_errors=True)
    os.makedirs(out)
    sim = subprocess.Popen(
        [binary, "sim-device", "stepper", "--motion", MOTION],
        stdout=subprocess.PIPE,
        stderr=open(os.path.join(out, "sim.log"), "w"),
        text=True,
    )
    try:
        port = sim.stdout.readline().strip()
        if not port:
            fail("the simulated bench did not start")
        run = subprocess.Popen(
            [binary, "measure", "--rig", RIG, "--port", port, "--motion", MOTION,
             "--cycles", "30", "--no-analysis", "--live", "-o", os.path.join(out, "rec")],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        first = run.stderr.readline()
        prefix, suffix = "live view: ", " (open it in a browser)\n"
        if not (first.startswith(prefix) and first.endswith(suffix)):
            run.kill()
            fail(f"measure --live printed {first!r} first")
        url = first[len(prefix):-len(suffix)]
        deadline = time.time() + 30
        while state(url)["status"] is None or state(url)["status"]["phase"] != "forward":
            if time.time() > deadline:
                run.kill()
                fail("the run did not reach its forward phase in 30 s")
            time.sleep(0.2)

        browser = [chromium, "--headless", "--no-sandbox", "--disable-gpu",
                   "--hide-scrollbars", "--window-size=1200,900",
                   "--virtual-time-budget=2000", "--enable-logging=stderr", "--v=0"]
        dom = subprocess.run(browser + ["--dump-dom", url], capture_output=True, text=True,
                             timeout=120)
        subprocess.run(browser + [f"--screenshot={os.path.join(out, 'live-view.png')}", url],
                       capture_output=True, timeout=120)
        with open(os.path.join(out, "browser.log"), "w") as f:
            f.write(dom.stderr)
        figures = Figures()
        figures.feed(dom.stdout)
        text = figures.text
        problems = []
        if text.get("run") != "half-turn-2to1 (1R)":
            problems.append(f"run shown as {text.get('run')!r}")
        if text.get("state") != "running":
            problems.append(f"state shown as {text.get('state')!r}")
        if not text.get("f-samples", "").isdigit() or int(text["f-samples"]) == 0:
            problems.append(f"samples shown as {text.get('f-samples')!r}")
        if not text.get("f-rate", "").endswith(" Hz"):
            problems.append(f"rate shown as {text.get('f-rate')!r}")
        if text.get("f-phase") not in ("forward", "settle"):
            problems.append(f"phase shown as {text.get('f-phase')!r}")
        if text.get("note"):
            problems.append(f"the page says {text['note']!r}")
        errors = [line for line in dom.stderr.splitlines()
                  if "CONSOLE" in line and ("Uncaught" in line or "Error" in line)]
        problems += [f"console: {e}" for e in errors]

        urllib.request.urlopen(urllib.request.Request(f"{url}stop", method="POST"), timeout=5)
        code = run.wait(timeout=60)
        rest = run.stderr.read()
        if code != 130:
            problems.append(f"after Stop, exit code {code} (expected 130): {rest}")
        with open(os.path.join(out, "rec", "recording.json")) as f:
            meta = json.load(f)
        if meta.get("end_reason") != "cancelled" or meta.get("complete"):
            problems.append(f"recording ended {meta.get('end_reason')!r}, complete {meta.get('complete')}")
        if problems:
            for p in problems:
                print(f"FAIL: {p}")
            sys.exit(1)
        print(f"live view in {chromium}: {text['run']}, {text['f-samples']} samples at "
              f"{text['f-rate']}, phase {text['f-phase']}; Stop ended the run (exit 130, "
              f"recording cancelled); screenshot {os.path.join(out, 'live-view.png')}")
    finally:
        sim.terminate()
        sim.wait(timeout=10)


if __name__ == "__main__":
    main()

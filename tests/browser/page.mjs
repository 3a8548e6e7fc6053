#!/usr/bin/env node
// Drive what lodconvert's viewer page shows of itself in headless Chromium, apart from the model:
// its readout panel folding, and its alert box when the viewer library or the model cannot be
// loaded; print what it saw as one line of JSON. Its command line, output, waits and hang guard
// are those of harness.mjs (see there):
//
//   node tests/browser/page.mjs SCENARIO BASE_URL PARAMS_JSON
//
// SCENARIO: panel or alert (PARAMS: see each below).

import { doing, evaluate, openViewer, run, waitFor } from "./harness.mjs";

const scenarios = {
  /**
   * lodconvert's viewer page params.page: its readout panel as first shown, once folded by a
   * click on its heading (and the viewer moved to params.distance meanwhile) and once unfolded
   * by another: open, height, whether the readout shows and its text, and whether the view is
   * what shows where the middle of the readout first showed.
   */
  async panel(page, { base, params }) {
    await openViewer(page, base, params.page);
    const heading = page.locator("#panel > summary");
    if ((await heading.count()) === 0) throw new Error("the panel has no heading to fold it by");
    const look = (at) => {
      const panel = document.getElementById("panel");
      const readout = document.getElementById("readout");
      const box = readout.getBoundingClientRect();
      const middle = at ?? { x: box.left + box.width / 2, y: box.top + box.height / 2 };
      return {
        open: panel.open,
        height: panel.getBoundingClientRect().height,
        readoutShown: readout.checkVisibility(),
        readout: readout.textContent,
        at: middle,
        view: document.getElementById("view").contains(
          document.elementFromPoint(middle.x, middle.y),
        ),
      };
    };
    const first = await evaluate(page, "reading the panel", look, null);
    doing("clicking the panel's heading");
    await heading.click();
    const move = (d) => window.lodconvertViewer.setDistance(d);
    await evaluate(page, `moving to ${params.distance}`, move, params.distance);
    const folded = await evaluate(page, "reading the folded panel", look, first.at);
    doing("clicking the panel's heading again");
    await heading.click();
    const unfolded = await evaluate(page, "reading the unfolded panel", look, first.at);
    return { first, folded, unfolded };
  },

  /**
   * lodconvert's viewer page params.page, expected to alert: once it is ready, has an error or
   * shows its alert box, that error and the box (text, and whether it shows: visible, sized).
   */
  async alert(page, { base, params }) {
    doing(`loading the viewer page ${params.page}`);
    await page.goto(`${base}/${params.page}`);
    await waitFor(page, "the viewer page alerting", () => {
      const viewer = window.lodconvertViewer;
      return viewer?.ready || viewer?.error || document.getElementById("problem")?.hidden === false;
    });
    return evaluate(page, "reading its alert box", () => {
      const box = document.getElementById("problem");
      const { width, height } = box?.getBoundingClientRect() ?? { width: 0, height: 0 };
      const { ready, error } = window.lodconvertViewer;
      const shown = Boolean(box?.checkVisibility()) && width > 0 && height > 0;
      return { ready, error, shown, text: box?.textContent ?? null };
    });
  },
};

run(scenarios);

// Pixels of the viewer's canvas for the end-to-end tests: a screenshot
// read back in the page (a 2D canvas), measured there.

// A screenshot of the canvas (saved to `file` when given): {b64, box}.
export async function canvasShot(page, file) {
  const canvas = page.locator('#view canvas');
  const box = await canvas.boundingBox();
  const buf = await canvas.screenshot(file ? { path: file } : {});
  return { b64: buf.toString('base64'), box };
}

// Runs `measure(data, width, height, arg, disc)` in the page on the shot's
// RGBA. disc(x, y, r, visit) calls visit(i) with the RGBA index of every
// pixel within `r` px of (x, y) and inside the shot; it returns their count.
function inPage(page, shot, measure, arg) {
  return page.evaluate(async ({ b64, src, arg }) => {
    const img = new Image();
    img.src = `data:image/png;base64,${b64}`;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.width;
    c.height = img.height;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const d = g.getImageData(0, 0, c.width, c.height).data;
    const w = c.width;
    const h = c.height;
    const disc = (x, y, r, visit) => {
      let n = 0;
      for (let dy = -r; dy <= r; ++dy) {
        for (let dx = -r; dx <= r; ++dx) {
          const px = Math.round(x) + dx;
          const py = Math.round(y) + dy;
          if (dx * dx + dy * dy > r * r || px < 0 || py < 0 || px >= w || py >= h) continue;
          n++;
          visit(4 * (py * w + px));
        }
      }
      return n;
    };
    // eslint-disable-next-line no-new-func
    return new Function('d', 'w', 'h', 'arg', 'disc', src)(d, w, h, arg, disc);
  }, { b64: shot.b64, src: `return (${measure.toString()})(d, w, h, arg, disc);`, arg });
}

// The share of all the shot's pixels that are purple (the low end of the
// colour map: red and blue well above green).
export function purpleShare(page, shot) {
  return inPage(page, shot, (d) => {
    let purple = 0;
    for (let i = 0; i < d.length; i += 4) {
      if (d[i] > d[i + 1] + 30 && d[i + 2] > d[i + 1] + 30) purple++;
    }
    return purple / (d.length / 4);
  });
}

// The mean colour over 5 x 5 pixels at client point `at`.
export function colourAt(page, shot, at) {
  return inPage(page, shot, (d, w, h, { x, y }) => {
    const sum = [0, 0, 0];
    for (let dy = -2; dy <= 2; ++dy) {
      for (let dx = -2; dx <= 2; ++dx) {
        const i = 4 * ((Math.round(y) + dy) * w + Math.round(x) + dx);
        for (let k = 0; k < 3; ++k) sum[k] += d[i + k] / 25;
      }
    }
    return sum.map(Math.round);
  }, { x: at.x - shot.box.x, y: at.y - shot.box.y });
}

// The brush colour (0xffe070: red and green high, blue low) around client
// point `at`: {share} of the pixels within `r` px that have it, and
// {centre}: whether the 5 x 5 pixels at `at` have it.
export function yellowNear(page, shot, at, r) {
  return inPage(page, shot, (d, w, h, { x, y, r }, disc) => {
    const yellow = (i) => d[i] > 200 && d[i + 1] > 170 && d[i + 2] < 150 && d[i] - d[i + 2] > 90;
    let hit = 0;
    const n = disc(x, y, r, (i) => { if (yellow(i)) hit++; });
    let centre = 0;
    for (let dy = -2; dy <= 2; ++dy) {
      for (let dx = -2; dx <= 2; ++dx) if (yellow(4 * ((Math.round(y) + dy) * w + Math.round(x) + dx))) centre++;
    }
    return { share: hit / Math.max(n, 1), centre: centre >= 13 };
  }, { x: at.x - shot.box.x, y: at.y - shot.box.y, r });
}

// The share of the pixels within `r` px of client point `at` whose colour
// satisfies `test(r, g, b)` (a plain function: it runs in the page).
export function share(page, shot, at, r, test) {
  return inPage(page, shot, (d, w, h, { x, y, r, src }, disc) => {
    // eslint-disable-next-line no-new-func
    const ok = new Function(`return (${src});`)();
    let hit = 0;
    const n = disc(x, y, r, (i) => { if (ok(d[i], d[i + 1], d[i + 2])) hit++; });
    return hit / Math.max(n, 1);
  }, { x: at.x - shot.box.x, y: at.y - shot.box.y, r, src: test.toString() });
}

// What the page tells the person: the banner (a sentence, and for a
// refusal the server's exact words in a details line and its tooltip), a
// progress banner while something loads, and a small label next to the
// pointer (a brush's size while it changes, "no solid here").

const $ = (id) => document.getElementById(id);

export class Feedback {
  // `log`: an array the end-to-end tests read ({kind, text}, at most 50).
  constructor(log) {
    this.log = log;
    this.bannerTimer = null;
    this.hudTimer = null;
    this.progressTimer = null;
  }

  banner(text, kind = 'info', ms = 6000, detail = '') {
    this.stopProgress();
    const b = $('banner');
    b.textContent = '';
    const main = document.createElement('div');
    main.className = 'text';
    main.textContent = text;
    b.appendChild(main);
    if (detail) {
      const d = document.createElement('div');
      d.className = 'detail';
      d.textContent = detail;
      b.appendChild(d);
    }
    b.title = detail || '';
    b.className = kind;
    b.hidden = false;
    clearTimeout(this.bannerTimer);
    if (ms) this.bannerTimer = setTimeout(() => { b.hidden = true; }, ms);
    this.log.push({ kind, text: detail ? `${text} ${detail}` : text });
    if (this.log.length > 50) this.log.shift();
  }

  // A banner with a moving bar and the seconds so far, until the next
  // banner (or done()).
  progress(text) {
    this.banner(text, 'progress', 0);
    const b = $('banner');
    const bar = document.createElement('div');
    bar.className = 'progress';
    bar.appendChild(document.createElement('div'));
    b.appendChild(bar);
    const t0 = performance.now();
    const main = b.querySelector('.text');
    const tick = () => {
      main.textContent = `${text} ${((performance.now() - t0) / 1000).toFixed(1)} s`;
    };
    tick();
    this.progressTimer = setInterval(tick, 100);
  }

  stopProgress() {
    clearInterval(this.progressTimer);
    this.progressTimer = null;
  }

  get inProgress() {
    return this.progressTimer !== null;
  }

  // A label next to the pointer at client (x, y) for `ms`.
  hud(text, x, y, ms = 1200) {
    const h = $('hud');
    const view = $('view').getBoundingClientRect();
    h.textContent = text;
    h.style.left = `${Math.round(x - view.left + 16)}px`;
    h.style.top = `${Math.round(y - view.top + 14)}px`;
    h.hidden = false;
    clearTimeout(this.hudTimer);
    this.hudTimer = setTimeout(() => { h.hidden = true; }, ms);
  }
}

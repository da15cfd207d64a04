// The help overlay: the mouse and the shortcuts, shown on a person's first
// visit (remembered in localStorage), closed with its button, Esc or a
// click beside it, and opened again with `?` or the panel's Help button.

const $ = (id) => document.getElementById(id);
export const HELP_SEEN_KEY = 'dynsolid.help.seen';

function seen() {
  try {
    return localStorage.getItem(HELP_SEEN_KEY) === '1';
  } catch (e) {
    return false;  // storage blocked: show it, it cannot be remembered
  }
}

export class Help {
  constructor() {
    this.box = $('help');
    $('help-close').onclick = () => this.close();
    $('help-open').onclick = () => this.open();
    // A click on the backdrop, not on the card, closes it.
    this.box.addEventListener('pointerdown', (e) => {
      if (e.target === this.box) this.close();
    });
    if (!seen()) this.open();
  }

  get isOpen() {
    return !this.box.hidden;
  }

  open() {
    this.box.hidden = false;
    $('help-close').focus();
  }

  close() {
    this.box.hidden = true;
    try {
      localStorage.setItem(HELP_SEEN_KEY, '1');
    } catch (e) {
      // storage blocked: it shows again next time
    }
  }

  toggle() {
    if (this.isOpen) this.close();
    else this.open();
  }
}

// The scene editor: a plain <textarea> (so copy/paste, undo and every browser's editing keys
// just work) over a backdrop that highlights lines, with a line-number gutter, one-line notes
// at the end of the offending lines and a full list of errors below. A 422 from the server
// names each error by a JSON pointer into the submitted document; jsonpos.js maps pointers
// to offsets in the text, so the note lands on the line of that key even after edits.

import { el } from './util.js';
import { parseWithPositions, locate, lineOf, JsonSyntaxError } from './jsonpos.js';

export class SceneEditor {
  /** `root` is an empty element; the editor builds its DOM inside. */
  constructor(root) {
    this.root = root;
    this.errors = []; // [{pointer, message}] from the last submission
    this.syntax = null; // {line, message} while the text is not JSON
    this.textarea = el('textarea', {
      class: 'editor-text',
      spellcheck: 'false',
      autocapitalize: 'off',
      autocomplete: 'off',
      wrap: 'off',
      'aria-label': 'Scene JSON',
      id: 'scene-text',
    });
    this.gutter = el('pre', { 'aria-hidden': 'true' });
    this.backdrop = el('div', { class: 'editor-backdrop', 'aria-hidden': 'true' });
    this.notes = el('div', { class: 'editor-notes' });
    this.list = el('ul', { class: 'error-list', id: 'scene-errors', 'aria-live': 'polite' });
    const main = el('div', { class: 'editor-main' }, this.backdrop, this.textarea, this.notes);
    root.append(el('div', { class: 'editor' }, el('div', { class: 'editor-gutter' }, this.gutter), main), this.list);

    // Re-layout on every edit: line numbers, syntax check, and the notes follow their keys.
    let pending = 0;
    this.textarea.addEventListener('input', () => {
      cancelAnimationFrame(pending);
      pending = requestAnimationFrame(() => this.render());
    });
    this.textarea.addEventListener('scroll', () => this.syncScroll());
    this.render();
  }

  get text() {
    return this.textarea.value;
  }

  set text(t) {
    this.textarea.value = t;
    this.loaded = t;
    this.errors = [];
    this.render();
    this.textarea.scrollTop = 0;
  }

  /** Puts back a text kept over a reload: `text` as edited from `loaded`. */
  restore(text, loaded) {
    this.text = loaded;
    this.textarea.value = text;
    this.render();
  }

  /** Scrolls the line of the syntax error (if any) into the middle of the editor. */
  revealSyntax() {
    if (!this.syntax) return;
    const lines = this.text.split('\n');
    const start = lines.slice(0, this.syntax.line).reduce((n, l) => n + l.length + 1, 0);
    this.textarea.setSelectionRange(start, start);
    const h = this.lineHeight();
    this.textarea.scrollTop = Math.max(0, this.syntax.line * h - this.textarea.clientHeight / 2 + h);
    this.syncScroll();
  }

  /** True when the user changed the text since it was last set by the program. */
  get edited() {
    return this.textarea.value !== (this.loaded ?? '');
  }

  /** The parsed document, or null after showing where the syntax is wrong. */
  parse() {
    try {
      return parseWithPositions(this.text).value;
    } catch (e) {
      if (!(e instanceof JsonSyntaxError)) throw e;
      this.render();
      return null;
    }
  }

  /** Shows the server's field errors ([{pointer, message}]). */
  showErrors(errors) {
    // The same message twice for one pointer is said once.
    const seen = new Set();
    this.errors = errors.filter((e) => {
      const key = `${e.pointer}\n${e.message}`;
      if (seen.has(key)) return false;
      seen.add(key);
      return true;
    });
    this.render();
    // Bring the first error into view: users should not have to hunt for it.
    const first = this.notes.querySelector('.note');
    if (first) this.textarea.scrollTop = Math.max(0, Number(first.dataset.line) * this.lineHeight() - 40);
    this.syncScroll();
  }

  clearErrors() {
    this.showErrors([]);
  }

  lineHeight() {
    return parseFloat(getComputedStyle(this.textarea).lineHeight) || 20;
  }

  /** Maps every error to a line; errors whose pointer is not in the text go to the root. */
  placeErrors(text) {
    let positions = null;
    this.syntax = null;
    try {
      positions = parseWithPositions(text).positions;
    } catch (e) {
      if (!(e instanceof JsonSyntaxError)) throw e;
      this.syntax = { line: lineOf(text, e.offset), message: `JSON syntax: ${e.message}` };
    }
    return this.errors.map((err) => {
      const pos = positions ? locate(positions, err.pointer) : null;
      const line = pos ? lineOf(text, pos.keyStart) : null;
      return { ...err, line, exact: pos ? pos.exact : false, pos };
    });
  }

  render() {
    const text = this.text;
    const lines = text.split('\n');
    const placed = this.placeErrors(text);
    const byLine = new Map();
    for (const p of placed) {
      if (p.line === null) continue;
      if (!byLine.has(p.line)) byLine.set(p.line, []);
      byLine.get(p.line).push(p);
    }
    if (this.syntax) {
      if (!byLine.has(this.syntax.line)) byLine.set(this.syntax.line, []);
      byLine.get(this.syntax.line).push({ pointer: null, message: this.syntax.message, syntax: true });
    }

    this.gutter.textContent = lines.map((_, i) => i + 1).join('\n') + '\n';
    // The backdrop repeats the text (transparent) so highlighted lines have the exact height
    // and width of the textarea's lines.
    this.backdrop.replaceChildren(
      ...lines.map((l, i) => el('div', { class: byLine.has(i) ? 'line bad' : 'line' }, l || ' ')),
    );
    // Each note sits in an anchor with the editor's monospace font, so `ch` is the width of
    // one character of the text: the note starts just past the end of its line.
    this.notes.replaceChildren(
      ...[...byLine.entries()].map(([line, errs]) =>
        el(
          'div',
          {
            class: 'note-anchor',
            style: `top: calc(${line} * var(--line) + 6px); left: calc(${lines[line].length + 2}ch + 8px)`,
          },
          el(
            'span',
            {
              class: errs.some((e) => e.syntax) ? 'note syntax' : 'note',
              dataset: { line: String(line), pointer: errs.map((e) => e.pointer ?? '').join(' ') },
              title: errs.map((e) => e.message).join('\n'),
            },
            // On the line of its own key a message needs no pointer (it would take a third
            // of the room); one placed elsewhere, or beside another key's, names its key.
            errs.map((e) => (e.pointer === null || (e.exact && new Set(errs.map((x) => x.pointer)).size === 1)
              ? e.message
              : `${e.pointer}: ${e.message}`)).join(' · '),
          ),
        ),
      ),
    );
    this.list.replaceChildren(
      ...(this.syntax ? [el('li', { class: 'syntax' }, `line ${this.syntax.line + 1}: ${this.syntax.message}`)] : []),
      ...placed.map((p) =>
        el(
          'li',
          {
            dataset: { pointer: p.pointer },
            tabindex: '0',
            title: 'show in the editor',
            onclick: () => this.select(p),
            onkeydown: (ev) => ev.key === 'Enter' && this.select(p),
          },
          el('code', {}, p.pointer || '(document)'),
          p.line !== null ? el('span', { class: 'where' }, ` line ${p.line + 1}${p.exact ? '' : ' (missing here)'}`) : null,
          ': ',
          el('span', { class: 'msg' }, p.message),
        ),
      ),
    );
    this.root.classList.toggle('has-errors', placed.length > 0 || !!this.syntax);
    this.syncScroll();
  }

  /** Selects the key and value of an error in the textarea. */
  select(p) {
    if (!p.pos) return;
    this.textarea.focus();
    this.textarea.setSelectionRange(p.pos.keyStart, p.pos.end);
    this.textarea.scrollTop = Math.max(0, p.line * this.lineHeight() - 40);
    this.syncScroll();
  }

  syncScroll() {
    const { scrollTop: y, scrollLeft: x } = this.textarea;
    this.backdrop.style.transform = `translate(${-x}px, ${-y}px)`;
    this.notes.style.transform = `translate(${-x}px, ${-y}px)`;
    this.gutter.style.transform = `translateY(${-y}px)`;
  }
}

// Where is each JSON pointer in a text? A small JSON parser that, besides checking the
// syntax, records for every value the offsets of its key (or array slot) and its value, so a
// server error at "/boundary/2/to" can be drawn on the line the user actually typed it.
// (JSON.parse gives values, not positions.)

/** RFC 6901: "/a~1b/0" -> ["a/b", "0"]. */
export function splitPointer(ptr) {
  if (ptr === '' || ptr === '/') return ptr === '' ? [] : [''];
  return ptr
    .replace(/^\//, '')
    .split('/')
    .map((s) => s.replace(/~1/g, '/').replace(/~0/g, '~'));
}

export function joinPointer(parts) {
  return parts.map((p) => '/' + String(p).replace(/~/g, '~0').replace(/\//g, '~1')).join('');
}

export class JsonSyntaxError extends Error {
  constructor(message, offset) {
    super(message);
    this.offset = offset;
  }
}

/**
 * Parses `text`; returns {value, positions} where positions maps a pointer ("" for the root)
 * to {start, end, keyStart} (character offsets; keyStart is the key's offset for object
 * members, else the value's). Throws JsonSyntaxError with the offset of the problem.
 */
export function parseWithPositions(text) {
  let i = 0;
  const positions = new Map();
  const fail = (msg) => {
    throw new JsonSyntaxError(msg, i);
  };
  const ws = () => {
    while (i < text.length && ' \t\n\r'.includes(text[i])) i++;
  };
  const str = () => {
    // JSON.parse does the unescaping once the extent of the string is known.
    const start = i++;
    while (i < text.length && text[i] !== '"') {
      if (text[i] === '\\') i++;
      else if (text[i] === '\n') fail('unterminated string');
      i++;
    }
    if (i >= text.length) fail('unterminated string');
    i++;
    try {
      return JSON.parse(text.slice(start, i));
    } catch {
      i = start;
      return fail('invalid string escape');
    }
  };
  const value = (path, keyStart) => {
    ws();
    const start = i;
    let v;
    const c = text[i];
    if (c === '{') {
      v = {};
      i++;
      ws();
      if (text[i] === '}') i++;
      else {
        for (;;) {
          ws();
          if (text[i] !== '"') fail('expected a "key"');
          const ks = i;
          const k = str();
          ws();
          if (text[i] !== ':') fail('expected ":" after a key');
          i++;
          v[k] = value([...path, k], ks);
          ws();
          if (text[i] === ',') {
            i++;
            continue;
          }
          if (text[i] === '}') {
            i++;
            break;
          }
          fail('expected "," or "}"');
        }
      }
    } else if (c === '[') {
      v = [];
      i++;
      ws();
      if (text[i] === ']') i++;
      else {
        for (;;) {
          ws();
          v.push(value([...path, v.length], i));
          ws();
          if (text[i] === ',') {
            i++;
            continue;
          }
          if (text[i] === ']') {
            i++;
            break;
          }
          fail('expected "," or "]"');
        }
      }
    } else if (c === '"') {
      v = str();
    } else {
      const m = /^(-?(?:0|[1-9]\d*)(?:\.\d+)?(?:[eE][+-]?\d+)?|true|false|null)/.exec(text.slice(i, i + 64));
      if (!m) fail(i >= text.length ? 'unexpected end of the text' : `unexpected character ${JSON.stringify(c)}`);
      v = JSON.parse(m[1]);
      i += m[1].length;
    }
    positions.set(joinPointer(path), { start, end: i, keyStart: keyStart ?? start });
    return v;
  };
  const v = value([], 0);
  ws();
  if (i < text.length) fail('unexpected text after the document');
  return { value: v, positions };
}

/**
 * The position of `pointer`, or of its nearest ancestor that exists (a missing field is
 * reported at its parent object), with `exact` telling which.
 */
export function locate(positions, pointer) {
  let parts = splitPointer(pointer);
  for (;;) {
    const p = positions.get(joinPointer(parts));
    if (p) return { ...p, exact: parts.length === splitPointer(pointer).length };
    if (parts.length === 0) return null;
    parts = parts.slice(0, -1);
  }
}

/** 0-based line of a character offset. */
export function lineOf(text, offset) {
  let n = 0;
  for (let j = 0; j < offset && j < text.length; j++) if (text.charCodeAt(j) === 10) n++;
  return n;
}

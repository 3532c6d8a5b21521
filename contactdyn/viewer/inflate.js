// contactdyn: gunzip, synchronously, for the exported HTML player (contactdyn/viewer/export.py).
// The payload is decoded while the page's script runs, so the scene is drawn before the page's
// load event (a plain `chromium --headless --screenshot` then shows it). DEFLATE (RFC 1951)
// decoded with canonical Huffman tables counted per code length; gzip (RFC 1952) framing as
// Python's gzip.compress writes it (no optional fields expected, but skipped if present).
var contactdynInflate = (function () {
  "use strict";
  var LENGTH_BASE = [3, 4, 5, 6, 7, 8, 9, 10, 11, 13, 15, 17, 19, 23, 27, 31, 35, 43, 51, 59, 67, 83, 99, 115,
                     131, 163, 195, 227, 258];
  var LENGTH_EXTRA = [0, 0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2, 3, 3, 3, 3, 4, 4, 4, 4, 5, 5, 5, 5, 0];
  var DIST_BASE = [1, 2, 3, 4, 5, 7, 9, 13, 17, 25, 33, 49, 65, 97, 129, 193, 257, 385, 513, 769, 1025, 1537,
                   2049, 3073, 4097, 6145, 8193, 12289, 16385, 24577];
  var DIST_EXTRA = [0, 0, 0, 0, 1, 1, 2, 2, 3, 3, 4, 4, 5, 5, 6, 6, 7, 7, 8, 8, 9, 9, 10, 10, 11, 11, 12, 12,
                    13, 13];
  var CODE_ORDER = [16, 17, 18, 0, 8, 7, 9, 6, 10, 5, 11, 4, 12, 3, 13, 2, 14, 1, 15];

  function Tree() { this.counts = new Uint16Array(16); this.symbols = new Uint16Array(288); }

  // counts[len]: codes of each length; symbols: the symbols in canonical order
  function build(tree, lengths, offset, n) {
    var i, offs = new Uint16Array(16), sum = 0;
    tree.counts.fill(0);
    for (i = 0; i < n; i++) tree.counts[lengths[offset + i]]++;
    tree.counts[0] = 0;
    for (i = 0; i < 16; i++) { offs[i] = sum; sum += tree.counts[i]; }
    for (i = 0; i < n; i++) if (lengths[offset + i]) tree.symbols[offs[lengths[offset + i]]++] = i;
  }

  function Reader(data, pos) { this.data = data; this.pos = pos; this.bits = 0; this.count = 0; }
  Reader.prototype.bit = function () {
    if (this.count === 0) {
      if (this.pos >= this.data.length) throw new Error("gunzip: the data end early");
      this.bits = this.data[this.pos++]; this.count = 8;
    }
    var b = this.bits & 1; this.bits >>>= 1; this.count--; return b;
  };
  Reader.prototype.read = function (n) {  // n bits, least significant first
    var v = 0;
    for (var i = 0; i < n; i++) v |= this.bit() << i;
    return v;
  };
  Reader.prototype.decode = function (tree) {  // one symbol: walk the code lengths
    var sum = 0, cur = 0, len = 0;
    do {
      cur = 2 * cur + this.bit(); len++;
      if (len > 15) throw new Error("gunzip: a bad Huffman code");
      sum += tree.counts[len]; cur -= tree.counts[len];
    } while (cur >= 0);
    return tree.symbols[sum + cur];
  };

  var FIXED_LIT = new Tree(), FIXED_DIST = new Tree();
  (function () {
    var l = new Uint8Array(288), i;
    for (i = 0; i < 144; i++) l[i] = 8;
    for (; i < 256; i++) l[i] = 9;
    for (; i < 280; i++) l[i] = 7;
    for (; i < 288; i++) l[i] = 8;
    build(FIXED_LIT, l, 0, 288);
    var d = new Uint8Array(30).fill(5);
    build(FIXED_DIST, d, 0, 30);
  })();

  function dynamicTrees(r, lit, dist) {
    var hlit = r.read(5) + 257, hdist = r.read(5) + 1, hclen = r.read(4) + 4, i;
    var lengths = new Uint8Array(320), codeTree = new Tree();
    for (i = 0; i < hclen; i++) lengths[CODE_ORDER[i]] = r.read(3);
    build(codeTree, lengths, 0, 19);
    lengths.fill(0);
    for (i = 0; i < hlit + hdist;) {
      var sym = r.decode(codeTree), rep, value = 0;
      if (sym < 16) { lengths[i++] = sym; continue; }
      if (sym === 16) { if (i === 0) throw new Error("gunzip: a repeat with nothing before"); value = lengths[i - 1]; rep = 3 + r.read(2); }
      else if (sym === 17) rep = 3 + r.read(3);
      else rep = 11 + r.read(7);
      while (rep--) lengths[i++] = value;
    }
    build(lit, lengths, 0, hlit);
    build(dist, lengths, hlit, hdist);
  }

  function inflate(r, out) {
    var n = 0, last, lit = new Tree(), dist = new Tree();
    function put(b) {
      if (n >= out.length) { var bigger = new Uint8Array(2 * out.length + 1024); bigger.set(out); out = bigger; }
      out[n++] = b;
    }
    do {
      last = r.bit();
      var type = r.read(2);
      if (type === 0) {  // stored: byte aligned, LEN and NLEN
        r.count = 0;
        var len = r.data[r.pos] | (r.data[r.pos + 1] << 8);
        r.pos += 4;
        for (var k = 0; k < len; k++) put(r.data[r.pos++]);
        continue;
      }
      if (type === 3) throw new Error("gunzip: a bad block type");
      var L = FIXED_LIT, D = FIXED_DIST;
      if (type === 2) { dynamicTrees(r, lit, dist); L = lit; D = dist; }
      for (;;) {
        var sym = r.decode(L);
        if (sym === 256) break;
        if (sym < 256) { put(sym); continue; }
        sym -= 257;
        var length = LENGTH_BASE[sym] + r.read(LENGTH_EXTRA[sym]);
        var d = r.decode(D);
        var back = DIST_BASE[d] + r.read(DIST_EXTRA[d]);
        for (var j = 0; j < length; j++) put(out[n - back]);
      }
    } while (!last);
    return out.subarray(0, n);
  }

  return function gunzip(data) {
    if (data[0] !== 0x1f || data[1] !== 0x8b || data[2] !== 8) throw new Error("gunzip: not gzip data");
    var flags = data[3], pos = 10;
    if (flags & 4) pos += 2 + (data[pos] | (data[pos + 1] << 8));  // FEXTRA
    if (flags & 8) while (data[pos++]) {}  // FNAME
    if (flags & 16) while (data[pos++]) {}  // FCOMMENT
    if (flags & 2) pos += 2;  // FHCRC
    var n = data.length, size = (data[n - 4] | (data[n - 3] << 8) | (data[n - 2] << 16) | (data[n - 1] << 24)) >>> 0;
    return inflate(new Reader(data, pos), new Uint8Array(size || 1024));
  };
})();

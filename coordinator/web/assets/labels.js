// Where the live map's labels go: a greedy placement that keeps every
// label clear of every other label and of every marker, so that a crowd
// of tracks stays readable.
//
// Labels are placed one after the other, the most wanted first (the
// selected track, then the leaders, then the tracks in order). Each tries
// a few spots around its marker — right, upper right, lower right, left,
// upper left, lower left, above, below; the spot it had last time first,
// so labels do not jump between frames — and keeps the first whose box
// stays inside the map and meets no label placed before it and no marker.
// A label with no such spot is hidden (the page shows it while the
// pointer is on its marker), except a forced one (the selected track's),
// which takes its first spot inside the map anyway.
"use strict";

const Labels = (() => {
  const GAP = 3; // between a marker's box and its label
  const MARGIN = 1; // kept between any two boxes

  // The spots of a w × h label beside a marker of half-size r at (x, y).
  function spots(x, y, r, w, h) {
    const d = r + GAP;
    return [
      [x + d, y - h / 2], [x + r, y - d - h], [x + r, y + d],
      [x - d - w, y - h / 2], [x - r - w, y - d - h], [x - r - w, y + d],
      [x - w / 2, y - d - h], [x - w / 2, y + d],
    ].map(([left, top]) => ({ left, top, width: w, height: h }));
  }

  function overlap(a, b, margin) {
    return a.left < b.left + b.width + margin && b.left < a.left + a.width + margin &&
      a.top < b.top + b.height + margin && b.top < a.top + a.height + margin;
  }

  const inside = (box, area) => box.left >= area.left && box.top >= area.top &&
    box.left + box.width <= area.left + area.width && box.top + box.height <= area.top + area.height;

  // A box kept inside the area (as far as it fits).
  const clamp = (box, area) => ({
    ...box,
    left: Math.max(area.left, Math.min(box.left, area.left + area.width - box.width)),
    top: Math.max(area.top, Math.min(box.top, area.top + area.height - box.height)),
  });

  // items: [{key, x, y, r, width, height, forced}], most wanted first;
  // markers: boxes no label may cover; area: the map's box; previous: key
  // → the spot index it had. Answers key → {box, spot}, or key → null for
  // a label that is hidden.
  function place(items, markers, area, previous) {
    const placed = [], result = new Map();
    const free = (box) => inside(box, area) &&
      !placed.some((p) => overlap(box, p, MARGIN)) && !markers.some((m) => overlap(box, m, 0));
    for (const item of items) {
      const all = spots(item.x, item.y, item.r, item.width, item.height);
      const before = previous.get(item.key);
      const order = all.map((_, i) => i);
      if (before !== undefined) order.unshift(...order.splice(before, 1));
      let spot = order.find((i) => free(all[i]));
      let box = spot === undefined ? null : all[spot];
      if (!box && item.forced) { spot = 0; box = clamp(all[0], area); }
      if (box) placed.push(box);
      result.set(item.key, box ? { box, spot } : null);
    }
    return result;
  }

  // Every label at its first spot, collisions or not: the map before
  // placement, which the tests use to show that overlaps are seen.
  function unplaced(items) {
    return new Map(items.map((item) => {
      const box = spots(item.x, item.y, item.r, item.width, item.height)[0];
      return [item.key, { box, spot: 0 }];
    }));
  }

  // A marker of half-size r at (x, y), as a box.
  const markerBox = (x, y, r) => ({ left: x - r, top: y - r, width: 2 * r, height: 2 * r });

  return { place, unplaced, markerBox, spots, overlap };
})();

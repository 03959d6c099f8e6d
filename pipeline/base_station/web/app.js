// airground base station page: a WebSocket (/ws) brings "hello" (classes), "state" (JSON) and map tiles
// (binary); the canvas draws the semantic map, robots, trails, regions, claims, visited and failed goals.
// Plain JS, nothing from the network but this base station.
'use strict';
(function () {
  const canvas = document.getElementById('map');
  const ctx = canvas.getContext('2d');
  const classColors = new Map();  // class id -> [r, g, b]
  const classNames = new Map();
  const tiles = new Map();        // "tx,ty" -> {tx, ty, version, img}
  let tileCells = 64, resolution = 0.5;
  let state = null;
  let dirty = true;
  let userView = null;            // {cx, cy, scale} once the user panned or zoomed
  let view = {cx: 0, cy: 0, scale: 4};
  const stats = {connected: false, frames: 0, tiles: 0, robots: 0, regions: 0, claims: 0, visited: 0, failed: 0,
                 objects: 0, drawn: 0, drawnTiles: 0, drawnRobots: 0, drawnRegions: 0, lastStateSeq: -1, badFrames: 0};
  window.agStats = stats;
  window.agState = () => state;  // the last state message (tests, the console)
  const palette = ['#ffd24a', '#4ad9ff', '#ff7ad9', '#8cff6a', '#ff9a4a', '#b18cff', '#4affc3', '#ff4a6e'];
  const robotColor = (id) => id === 0 ? '#ffffff' : palette[(id - 1) % palette.length];

  // ------------------------------------------------------------------ transport
  function connect() {
    const ws = new WebSocket((location.protocol === 'https:' ? 'wss://' : 'ws://') + location.host + '/ws');
    ws.binaryType = 'arraybuffer';
    ws.onopen = () => { stats.connected = true; setConn(); };
    ws.onclose = () => { stats.connected = false; setConn(); setTimeout(connect, 1000); };
    ws.onerror = () => {};
    ws.onmessage = (ev) => {
      stats.frames++;
      if (typeof ev.data === 'string') {
        let m;
        try { m = JSON.parse(ev.data); } catch (e) { stats.badFrames++; return; }
        if (m.type === 'hello') onHello(m);
        else if (m.type === 'state') onState(m);
      } else {
        onTile(ev.data);
      }
    };
  }
  function setConn() {
    const el = document.getElementById('conn');
    el.textContent = stats.connected ? 'live' : 'disconnected — retrying';
    el.className = stats.connected ? 'ok' : 'bad';
  }
  function onHello(m) {
    tileCells = m.tile_cells; resolution = m.resolution_m;
    for (const c of m.classes) { classColors.set(c.id, c.color); classNames.set(c.id, c.name); }
    const lg = document.getElementById('legend');
    lg.innerHTML = m.classes.filter(c => c.id !== 255).map(c =>
      `<span style="background:rgb(${c.color.join(',')})"></span>${c.name}`).join('');
    for (const t of tiles.values()) paintTile(t);  // colours may have arrived after tiles
    dirty = true;
  }
  function onTile(buf) {
    const dv = new DataView(buf);
    if (buf.byteLength < 24 || dv.getUint8(0) !== 1) { stats.badFrames++; return; }
    const cells = dv.getUint16(2, true);
    const n = cells * cells;
    if (buf.byteLength !== 24 + n * 3) { stats.badFrames++; return; }
    const tx = dv.getInt32(4, true), ty = dv.getInt32(8, true);
    const version = Number(dv.getBigUint64(16, true));
    const key = tx + ',' + ty;
    const old = tiles.get(key);
    if (old && old.version >= version) return;
    const t = {tx, ty, version, cells, cls: new Uint8Array(buf, 24, n), img: null};
    paintTile(t);
    tiles.set(key, t);
    stats.tiles = tiles.size;
    dirty = true;
  }
  function paintTile(t) {
    const c = t.img || document.createElement('canvas');
    c.width = t.cells; c.height = t.cells;
    const g = c.getContext('2d');
    const im = g.createImageData(t.cells, t.cells);
    for (let row = 0; row < t.cells; row++) {          // row 0 = south
      const out = (t.cells - 1 - row) * t.cells;         // image row 0 = north
      for (let col = 0; col < t.cells; col++) {
        const k = t.cls[row * t.cells + col];
        const p = 4 * (out + col);
        const rgb = classColors.get(k);
        if (k === 255 || !rgb) { im.data[p + 3] = 0; continue; }
        im.data[p] = rgb[0]; im.data[p + 1] = rgb[1]; im.data[p + 2] = rgb[2]; im.data[p + 3] = 255;
      }
    }
    g.putImageData(im, 0, 0);
    t.img = c;
  }
  function onState(m) {
    state = m;
    stats.lastStateSeq = m.seq;
    stats.robots = m.robots.filter(r => r.has_pose).length;
    stats.regions = m.regions.list.length;
    stats.claims = m.robots.filter(r => r.claim && r.claim.region !== null && r.claim.region !== undefined).length;
    stats.visited = m.robots.reduce((a, r) => a + r.visited.length, 0);
    stats.failed = m.failures.length;
    stats.objects = m.objects.length;
    dirty = true;
    panels(m);
  }

  // ------------------------------------------------------------------ view
  function bounds() {
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    const add = (x, y) => { x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y); };
    const side = tileCells * resolution;
    for (const t of tiles.values()) { add(t.tx * side, t.ty * side); add((t.tx + 1) * side, (t.ty + 1) * side); }
    if (state) {
      for (const r of state.robots) if (r.has_pose) add(r.x, r.y);
      for (const g of state.regions.list) add(g.cx, g.cy);
    }
    if (!isFinite(x0)) return {x0: -50, y0: -50, x1: 50, y1: 50};
    return {x0: x0 - 10, y0: y0 - 10, x1: x1 + 10, y1: y1 + 10};
  }
  function fit() {
    const b = bounds();
    const scale = Math.min(canvas.width / (b.x1 - b.x0), canvas.height / (b.y1 - b.y0));
    return {cx: (b.x0 + b.x1) / 2, cy: (b.y0 + b.y1) / 2, scale};
  }
  const toCanvas = (x, y) => [canvas.width / 2 + (x - view.cx) * view.scale, canvas.height / 2 - (y - view.cy) * view.scale];
  const toWorld = (px, py) => [view.cx + (px - canvas.width / 2) / view.scale, view.cy - (py - canvas.height / 2) / view.scale];
  // For tests and tools: canvas pixel of a map point, and the view.
  window.agView = {toCanvas: (x, y) => toCanvas(x, y), toWorld: (px, py) => toWorld(px, py), view: () => ({...view}), redraw: () => draw()};

  // ------------------------------------------------------------------ drawing
  function draw() {
    const w = canvas.clientWidth, h = canvas.clientHeight;
    if (w > 0 && h > 0 && (canvas.width !== w || canvas.height !== h)) { canvas.width = w; canvas.height = h; }
    view = userView || fit();
    ctx.setTransform(1, 0, 0, 1, 0, 0);
    ctx.fillStyle = '#0d0f12';
    ctx.fillRect(0, 0, canvas.width, canvas.height);
    ctx.imageSmoothingEnabled = false;
    const side = tileCells * resolution;
    let nt = 0;
    for (const t of tiles.values()) {
      const [px, py] = toCanvas(t.tx * side, (t.ty + 1) * side);
      const s = side * view.scale;
      if (px > canvas.width || py > canvas.height || px + s < 0 || py + s < 0) continue;
      ctx.drawImage(t.img, px, py, s, s);
      nt++;
    }
    grid();
    let nreg = 0, nrob = 0;
    if (state) {
      const regionById = new Map(state.regions.list.map(g => [g.id, g]));
      for (const g of state.regions.list) {
        const [px, py] = toCanvas(g.cx, g.cy);
        const rad = Math.max(3, Math.sqrt(g.cells * resolution * resolution / Math.PI) + 2) * view.scale;
        ctx.strokeStyle = '#ffb347'; ctx.lineWidth = 2;
        ctx.beginPath(); ctx.arc(px, py, rad, 0, 2 * Math.PI); ctx.stroke();
        if (g.goal_valid) { const [gx, gy] = toCanvas(g.gx, g.gy); cross(gx, gy, 4, '#ffb347'); }
        ctx.fillStyle = '#ffb347'; ctx.font = '12px sans-serif';
        ctx.fillText(String(g.id), px + rad + 2, py - 2);
        nreg++;
      }
      for (const r of state.robots) {              // visited goals: green discs
        for (const v of r.visited) {
          const g = regionById.get(v.region);
          const [px, py] = toCanvas(g && g.goal_valid ? g.gx : v.x, g && g.goal_valid ? g.gy : v.y);
          ctx.fillStyle = 'rgba(60,220,90,0.85)';
          ctx.beginPath(); ctx.arc(px, py, 6, 0, 2 * Math.PI); ctx.fill();
        }
      }
      for (const f of state.failures) {            // failed goals: red crosses
        const [px, py] = toCanvas(f.x, f.y);
        ctx.lineWidth = 3; cross(px, py, 7, '#ff3b3b');
      }
      for (const o of state.objects) {             // detected objects: diamond + 2-sigma circle of the EKF
        const [px, py] = toCanvas(o.x, o.y);
        const sig = 2 * Math.sqrt(Math.max(o.cxx, o.cyy, 0)) * view.scale;
        ctx.strokeStyle = '#ff5cf0'; ctx.lineWidth = 1.5;
        if (sig > 2) { ctx.beginPath(); ctx.arc(px, py, sig, 0, 2 * Math.PI); ctx.stroke(); }
        ctx.fillStyle = '#ff5cf0';
        ctx.beginPath(); ctx.moveTo(px, py - 5); ctx.lineTo(px + 5, py); ctx.lineTo(px, py + 5); ctx.lineTo(px - 5, py); ctx.closePath(); ctx.fill();
      }
      for (const r of state.robots) {
        if (!r.has_pose) continue;
        const col = robotColor(r.id);
        if (r.trail.length >= 4) {
          ctx.strokeStyle = col; ctx.globalAlpha = 0.6; ctx.lineWidth = 2; ctx.beginPath();
          for (let i = 0; i < r.trail.length; i += 2) {
            const [px, py] = toCanvas(r.trail[i], r.trail[i + 1]);
            if (i === 0) ctx.moveTo(px, py); else ctx.lineTo(px, py);
          }
          ctx.stroke(); ctx.globalAlpha = 1;
        }
        if (r.claim && r.claim.region !== null && r.claim.state !== 'idle' && r.claim.state !== 'done') {
          const [ax, ay] = toCanvas(r.x, r.y), [bx, by] = toCanvas(r.claim.gx, r.claim.gy);
          ctx.strokeStyle = col; ctx.lineWidth = 1.5; ctx.setLineDash([6, 4]);
          ctx.beginPath(); ctx.moveTo(ax, ay); ctx.lineTo(bx, by); ctx.stroke(); ctx.setLineDash([]);
        }
        const [px, py] = toCanvas(r.x, r.y);
        const sig = Math.max(r.sx || 0, r.sy || 0) * view.scale;
        if (sig > 3) { ctx.strokeStyle = col; ctx.globalAlpha = 0.4; ctx.lineWidth = 1; ctx.beginPath(); ctx.arc(px, py, sig, 0, 2 * Math.PI); ctx.stroke(); ctx.globalAlpha = 1; }
        arrow(px, py, r.yaw, col, r.status);
        ctx.fillStyle = col; ctx.font = 'bold 12px sans-serif';
        ctx.fillText((r.id === 0 ? 'uav' : 'ugv') + r.id, px + 10, py + 14);
        nrob++;
      }
    }
    stats.drawn++; stats.drawnTiles = nt; stats.drawnRobots = nrob; stats.drawnRegions = nreg;
  }
  function grid() {
    const step = niceStep(80 / view.scale);
    const [wx0, wy1] = toWorld(0, 0), [wx1, wy0] = toWorld(canvas.width, canvas.height);
    ctx.strokeStyle = 'rgba(255,255,255,0.07)'; ctx.lineWidth = 1; ctx.beginPath();
    for (let x = Math.ceil(wx0 / step) * step; x < wx1; x += step) { const [px] = toCanvas(x, 0); ctx.moveTo(px, 0); ctx.lineTo(px, canvas.height); }
    for (let y = Math.ceil(wy0 / step) * step; y < wy1; y += step) { const [, py] = toCanvas(0, y); ctx.moveTo(0, py); ctx.lineTo(canvas.width, py); }
    ctx.stroke();
    ctx.fillStyle = '#889'; ctx.font = '11px sans-serif'; ctx.fillText(step + ' m grid', 8, 14);
  }
  function niceStep(v) { const p = Math.pow(10, Math.floor(Math.log10(v))); return [1, 2, 5, 10].map(k => k * p).find(s => s >= v); }
  function cross(x, y, s, col) {
    ctx.strokeStyle = col; ctx.beginPath(); ctx.moveTo(x - s, y - s); ctx.lineTo(x + s, y + s); ctx.moveTo(x - s, y + s); ctx.lineTo(x + s, y - s); ctx.stroke();
  }
  function arrow(x, y, yaw, col, status) {
    ctx.save(); ctx.translate(x, y); ctx.rotate(-yaw);
    ctx.fillStyle = col; ctx.strokeStyle = status === 'lost' ? '#ff3b3b' : '#000'; ctx.lineWidth = 2;
    ctx.beginPath(); ctx.moveTo(12, 0); ctx.lineTo(-8, 7); ctx.lineTo(-4, 0); ctx.lineTo(-8, -7); ctx.closePath();
    ctx.fill(); ctx.stroke(); ctx.restore();
  }

  // ------------------------------------------------------------------ panels
  const esc = (s) => String(s).replace(/[&<>]/g, c => ({'&': '&amp;', '<': '&lt;', '>': '&gt;'}[c]));
  const fmtB = (b) => b > 1e6 ? (b / 1e6).toFixed(1) + ' M' : b > 1e3 ? (b / 1e3).toFixed(1) + ' k' : String(b);
  function panels(m) {
    document.getElementById('summary').textContent =
      `t=${m.t.toFixed(0)} s · ${stats.robots} robots · ${tiles.size} tiles · ${m.regions.list.length} regions · ` +
      `${stats.visited} visited · ${m.failures.length} failed · ${m.objects.length} objects`;
    document.querySelector('#robots tbody').innerHTML = m.robots.map(r => {
      const c = r.claim;
      const goal = c ? `${esc(c.state)}${c.region !== null ? ' → ' + c.region : ''}` : '—';
      const st = r.has_pose ? r.status : 'no pose';
      const cls = st === 'tracking' ? 'ok' : st === 'lost' ? 'bad' : 'warn';
      return `<tr><td><span class="dot" style="background:${robotColor(r.id)}"></span>${r.id}</td><td class="${cls}">${esc(st)}</td>` +
        `<td>${r.has_pose ? r.x.toFixed(1) + ', ' + r.y.toFixed(1) : ''}</td><td>${r.has_pose ? Math.max(r.sx, r.sy).toFixed(2) : ''}</td>` +
        `<td>${goal}</td><td>${r.age_s.toFixed(1)} s ago</td>` +
        `<td><button data-cmd="arm" data-robot="${r.id}">arm</button> <button data-cmd="disarm" data-robot="${r.id}">disarm</button></td></tr>`;
    }).join('');
    document.getElementById('regver').textContent = m.regions.list.length ? `(version ${m.regions.version})` : '';
    const visited = new Set(); for (const r of m.robots) for (const v of r.visited) visited.add(v.region);
    const claimed = new Map(); for (const r of m.robots) if (r.claim && r.claim.region !== null) claimed.set(r.claim.region, r.id);
    document.getElementById('regions').innerHTML = m.regions.list.length === 0 ? 'none yet' : m.regions.list.map(g =>
      `<span class="${visited.has(g.id) ? 'ok' : claimed.has(g.id) ? 'warn' : ''}">${g.id}${claimed.has(g.id) ? '←' + claimed.get(g.id) : ''}</span>`).join(' · ');
    document.getElementById('failures').innerHTML = m.failures.length === 0 ? 'none' : m.failures.map(f =>
      `<div class="bad">robot ${f.robot}: region ${f.region} (${esc(f.reason)}, ${f.attempts} attempts) at ${f.x.toFixed(1)}, ${f.y.toFixed(1)}</div>`).join('');
    const c = m.comms;
    document.getElementById('commsum').textContent = c.present ?
      `${c.records} records (${fmtB(c.payload_bytes)}B) · in ${fmtB(c.bytes_in)}B · out ${fmtB(c.bytes_out)}B · drops ${c.drops}` : 'no comms counters yet';
    document.querySelector('#peers tbody').innerHTML = c.present ? c.peers.map(p =>
      `<tr><td>${p.id}</td><td>${fmtB(p.bytes_in)}</td><td>${fmtB(p.bytes_out)}</td><td>${p.records_in}</td>` +
      `<td class="${p.last_heard_s !== null && p.last_heard_s < 5 ? 'ok' : 'bad'}">${p.last_heard_s === null ? 'never' : p.last_heard_s.toFixed(1) + ' s ago'}</td></tr>`).join('') : '';
    const k = m.counters, s = m.server || {};
    document.getElementById('counters').textContent =
      `records ${k.records_in} · poses ${k.poses_in} · tiles ${k.tiles_in} · decode errors ${k.decode_errors}` +
      (k.last_error ? ` (last: ${k.last_error_kind} from ${k.last_error_origin}: ${k.last_error})` : '') +
      ` · log ${k.log_lines} lines · clients ${s.clients || 0} · bad requests ${s.bad_requests || 0}`;
  }

  // ------------------------------------------------------------------ interaction
  let drag = null;
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const v = userView || {...view};
    const [wx, wy] = toWorld(e.offsetX, e.offsetY);
    const k = e.deltaY < 0 ? 1.25 : 0.8;
    v.scale *= k; v.cx = wx - (wx - v.cx) / k; v.cy = wy - (wy - v.cy) / k;
    userView = v; dirty = true;
  }, {passive: false});
  canvas.addEventListener('mousedown', (e) => { drag = {x: e.offsetX, y: e.offsetY, v: {...(userView || view)}}; });
  window.addEventListener('mouseup', () => { drag = null; });
  canvas.addEventListener('mousemove', (e) => {
    if (!drag) return;
    userView = {cx: drag.v.cx - (e.offsetX - drag.x) / drag.v.scale, cy: drag.v.cy + (e.offsetY - drag.y) / drag.v.scale, scale: drag.v.scale};
    dirty = true;
  });
  canvas.addEventListener('dblclick', () => { userView = null; dirty = true; });
  // The operator's arm / disarm of a ground robot's wheels: POST to the base station, which sends it over the radio.
  document.querySelector('#robots tbody').addEventListener('click', (e) => {
    const b = e.target.closest('button[data-cmd]');
    if (!b) return;
    const what = `${b.dataset.cmd} robot ${b.dataset.robot}`;
    if (b.dataset.cmd === 'arm' && !window.confirm(`Arm robot ${b.dataset.robot}? Its wheels will drive.`)) return;
    fetch(`/api/${b.dataset.cmd}?robot=${encodeURIComponent(b.dataset.robot)}`, {method: 'POST'})
      .then(r => r.text().then(t => { document.getElementById('summary').title = `${what}: ${r.status} ${t}`; }))
      .catch(err => { document.getElementById('summary').title = `${what}: ${err}`; });
  });
  window.addEventListener('resize', () => { dirty = true; });

  function frame() { if (dirty) { dirty = false; draw(); } requestAnimationFrame(frame); }
  connect();
  requestAnimationFrame(frame);
})();

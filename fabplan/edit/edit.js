/* fabplan edit: handles, pins and drags on the reports' 3D view (viewer.js).
   The net comes from the server over a WebSocket (state messages with a scene); commands
   go back over it. The view's positions are model positions less the state's centre. */
(function () {
  'use strict';
  var token = new URLSearchParams(location.search).get('token') || '';
  var viewer = null, ws = null, state = null, normals = null, centre = [0, 0, 0];
  var tool = 'handle', moveMode = 'plane', drag = null, gestures = 0, down = null;
  var markers = null, stamps = [];
  var api = window.fabplanEdit = { state: null, lastTarget: null, sent: 0, updates: 0 };

  function $(sel) { return document.querySelector(sel); }
  function send(message) { if (ws && ws.readyState === 1) { ws.send(JSON.stringify(message)); api.sent++; } }

  function connect() {
    ws = new WebSocket('ws://' + location.host + '/ws?token=' + encodeURIComponent(token));
    ws.onmessage = function (ev) {
      var m = JSON.parse(ev.data);
      if (m.type === 'state') applyState(m);
      else if (m.type === 'error') $('.fe-message').textContent = m.message;
    };
    ws.onclose = function () { setStatus('disconnected: the server has ended', false); };
  }

  function setStatus(text, good) {
    var s = $('.fe-status');
    s.textContent = text;
    s.className = 'fe-status ' + (good ? 'fe-converged' : 'fe-failed');
  }

  function applyState(m) {
    var first = !viewer.data;
    state = api.state = m;
    centre = m.centre;
    if (m.scene) {
      viewer.scenes = [m.scene];
      viewer.setScene(0, !first);
      normals = m.normals;
    }
    api.updates++;
    var now = performance.now();
    stamps.push(now);
    while (stamps.length && stamps[0] < now - 2000) stamps.shift();
    var last = m.last || {};
    setStatus(m.status, m.status === 'converged');
    var parts = ['residual ' + (isFinite(m.residual) ? m.residual.toExponential(1) : '–') + ' edges'];
    if (last.iterations !== undefined) parts.push(last.iterations + ' iterations, ' + Math.round(1000 * last.seconds) + ' ms');
    parts.push(m.vertices + ' vertices, ' + Object.keys(m.handles).length + ' handles, ' + m.pins.length + ' pins');
    parts.push(m.unsaved ? 'unsaved' : (m.output ? 'saved' : ''));
    $('.fe-numbers').textContent = parts.join(' · ');
    $('.fe-message').textContent = m.status === 'converged' ? '' :
      m.message + (m.where.length ? ' (vertices ' + m.where.slice(0, 8).join(', ') + (m.where.length > 8 ? ', ...' : '') + ')' : '');
    $('.fe-undo').disabled = !m.undo; $('.fe-redo').disabled = !m.redo;
    var inf = $('.fe-influence');
    if (document.activeElement !== inf) inf.value = m.options.influence;
    drawMarkers();
    document.body.dataset.seq = m.seq;
  }

  function viewPoint(v) {     // (3,) view coordinates of vertex v
    var P = viewer.P;
    return new THREE.Vector3(P[3 * v], P[3 * v + 1], P[3 * v + 2]);
  }

  /* handles (orange), pins (blue) and failure places (red) as small octahedra drawn over
     the net, one mesh per kind (the vendored three.js has meshes, no sprites) */
  var OCTA = [[1, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 0], [-1, 0, 0], [0, 0, 1], [-1, 0, 0], [0, -1, 0], [0, 0, 1],
    [0, -1, 0], [1, 0, 0], [0, 0, 1], [0, 1, 0], [1, 0, 0], [0, 0, -1], [-1, 0, 0], [0, 1, 0], [0, 0, -1],
    [0, -1, 0], [-1, 0, 0], [0, 0, -1], [1, 0, 0], [0, -1, 0], [0, 0, -1]];
  function markerMesh(vertices, colour, size) {
    var pos = new Float32Array(3 * OCTA.length * vertices.length), i = 0;
    vertices.forEach(function (v) {
      var c = viewPoint(v);
      OCTA.forEach(function (o) { pos[i++] = c.x + size * o[0]; pos[i++] = c.y + size * o[1]; pos[i++] = c.z + size * o[2]; });
    });
    var g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    g.computeVertexNormals();
    var m = new THREE.Mesh(g, new THREE.MeshLambertMaterial({ color: colour, emissive: colour, emissiveIntensity: 0.5, depthTest: false }));
    m.renderOrder = 20;
    return m;
  }

  function drawMarkers() {
    (markers || []).forEach(function (m) { viewer.scene.remove(m); m.geometry.dispose(); });
    var r = 0.3 * state.mean_edge;
    markers = [markerMesh(Object.keys(state.handles).map(Number), 0xff7f0e, r),
      markerMesh(state.pins, 0x1f4e9a, 0.8 * r), markerMesh(state.where, 0xd62728, 0.6 * r)];
    markers.forEach(function (m) { viewer.scene.add(m); });
    viewer.render();
  }

  function screenOf(p) {
    var q = p.clone().project(viewer.camera), rect = viewer.renderer.domElement.getBoundingClientRect();
    return { x: rect.left + (q.x + 1) / 2 * rect.width, y: rect.top + (1 - q.y) / 2 * rect.height };
  }

  function rayAt(x, y) {
    var rect = viewer.renderer.domElement.getBoundingClientRect();
    var ndc = new THREE.Vector2(2 * (x - rect.left) / rect.width - 1, 1 - 2 * (y - rect.top) / rect.height);
    viewer.raycaster.setFromCamera(ndc, viewer.camera);
    return viewer.raycaster.ray;
  }

  /* the vertex under the pointer: the nearest corner of the panel hit, within 25 px */
  function vertexAt(x, y) {
    rayAt(x, y);
    var hit = viewer.raycaster.intersectObject(viewer.mesh, false)[0];
    if (!hit) return -1;
    var f = viewer.triFace[hit.faceIndex], best = -1, bestD = Infinity;
    for (var k = viewer.facePtr[f]; k < viewer.facePtr[f + 1]; k++) {
      var v = viewer.faceIndices[k], s = screenOf(viewPoint(v)), d = Math.hypot(s.x - x, s.y - y);
      if (d < bestD) { bestD = d; best = v; }
    }
    return bestD < 25 ? best : -1;
  }

  function handleAt(x, y) {
    var best = -1, bestD = 14;
    Object.keys(state.handles).forEach(function (k) {
      var s = screenOf(viewPoint(+k)), d = Math.hypot(s.x - x, s.y - y);
      if (d < bestD) { bestD = d; best = +k; }
    });
    return best;
  }

  /* where the dragged handle goes for the pointer at (x, y), in view coordinates */
  function dragPoint(x, y, alongNormal) {
    var ray = rayAt(x, y), p0 = drag.start, out = new THREE.Vector3();
    if (alongNormal) {      // the point of the normal line nearest to the pointer's ray
      var n = drag.normal, w = p0.clone().sub(ray.origin), b = n.dot(ray.direction);
      var denom = 1 - b * b;
      if (denom < 1e-9) return null;
      var t = (b * ray.direction.dot(w) - n.dot(w)) / denom;
      return p0.clone().addScaledVector(n, t);
    }
    // the plane through the handle facing the camera
    var denom2 = ray.direction.dot(drag.viewDir);
    if (Math.abs(denom2) < 1e-9) return null;
    var s = p0.clone().sub(ray.origin).dot(drag.viewDir) / denom2;
    return s > 0 ? out.copy(ray.origin).addScaledVector(ray.direction, s) : null;
  }

  function onDown(e) {
    if (!state || e.button !== 0) return;
    down = [e.clientX, e.clientY];
    var h = handleAt(e.clientX, e.clientY);
    if (h < 0) return;
    e.stopPropagation(); e.preventDefault();
    viewer.controls.enabled = false;
    var dir = new THREE.Vector3(); viewer.camera.getWorldDirection(dir);
    drag = { vertex: h, start: viewPoint(h), viewDir: dir, gesture: 'g' + (++gestures),
             normal: new THREE.Vector3(normals[3 * h], normals[3 * h + 1], normals[3 * h + 2]), pending: null };
    viewer.holder.setPointerCapture(e.pointerId);
  }

  function onMove(e) {
    if (!drag) return;
    e.stopPropagation();
    var p = dragPoint(e.clientX, e.clientY, e.shiftKey || moveMode === 'normal');
    if (!p) return;
    var target = [p.x + centre[0], p.y + centre[1], p.z + centre[2]];
    if (!drag.pending) requestAnimationFrame(flush);
    drag.pending = target;
  }

  function flush() {
    if (!drag || !drag.pending) return;
    var targets = {}; targets[drag.vertex] = drag.pending;
    api.lastTarget = { vertex: drag.vertex, target: drag.pending };
    send({ type: 'drag', targets: targets, gesture: drag.gesture });
    drag.pending = null;
  }

  function onUp(e) {
    if (drag) {
      e.stopPropagation();
      flush();
      send({ type: 'release' });
      viewer.controls.enabled = true;
      drag = null;
      return;
    }
    if (!down || Math.abs(e.clientX - down[0]) + Math.abs(e.clientY - down[1]) >= 5) return;
    down = null;
    var v = vertexAt(e.clientX, e.clientY);
    if (v < 0) return;
    var isHandle = state.handles[String(v)] !== undefined, isPin = state.pins.indexOf(v) >= 0;
    var role = tool === 'handle' ? (isHandle ? 'free' : 'handle') : (isPin ? 'free' : 'pin');
    send({ type: 'role', vertex: v, role: role });
  }

  function buttons(cls, key, set) {
    var all = document.querySelectorAll(cls);
    for (var i = 0; i < all.length; i++) all[i].onclick = function () {
      for (var j = 0; j < all.length; j++) all[j].classList.toggle('fe-on', all[j] === this);
      set(this.dataset[key]);
    };
  }

  function start() {
    viewer = window.fabplanViewers && window.fabplanViewers[0];
    if (!viewer) { setStatus('the 3D view needs WebGL', false); return; }
    buttons('.fe-tool', 'tool', function (v) { tool = v; });
    buttons('.fe-move', 'move', function (v) { moveMode = v; });
    ['undo', 'redo', 'reset', 'save'].forEach(function (k) {
      $('.fe-' + k).onclick = function () { send({ type: k }); };
    });
    $('.fe-influence').onchange = function () { send({ type: 'influence', value: +this.value }); };
    viewer.holder.addEventListener('pointerdown', onDown, true);
    viewer.holder.addEventListener('pointermove', onMove, true);
    viewer.holder.addEventListener('pointerup', onUp, true);
    api.screenPointOfVertex = function (v) { return screenOf(viewPoint(v)); };
    api.camera = function () {
      var d = new THREE.Vector3(); viewer.camera.getWorldDirection(d);
      var p = viewer.camera.position, rect = viewer.renderer.domElement.getBoundingClientRect();
      return { position: [p.x + centre[0], p.y + centre[1], p.z + centre[2]], direction: [d.x, d.y, d.z],
               fov: viewer.camera.fov, height: rect.height };
    };
    connect();
  }
  if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', start); else start();
})();

/* fabplan report 3D view: one viewer per div.fp-viewer, its scenes in a
   <script type="application/json"> inside it (written by fabplan/report/viewer.py).
   Needs the global THREE of vendor/three.min.js. Renders on demand (no animation loop). */
(function () {
  'use strict';
  var RAMP = [[0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530],
    [0.207, 0.372, 0.553], [0.164, 0.471, 0.558], [0.128, 0.567, 0.551],
    [0.135, 0.659, 0.518], [0.267, 0.749, 0.441], [0.478, 0.821, 0.318],
    [0.741, 0.873, 0.150], [0.993, 0.906, 0.144]];            // viridis
  var OVER = [0.84, 0.15, 0.16], NONE = [0.62, 0.62, 0.62], PLAIN = [0.86, 0.86, 0.84];
  var FAMILY = [[0.12, 0.37, 0.75], [0.88, 0.48, 0.0], [0.3, 0.3, 0.3]];

  var TYPES = { f4: Float32Array, i4: Int32Array, u2: Uint16Array, u1: Uint8Array, i1: Int8Array };
  function decode(text) {           // "TYPE:BASE64" (fabplan/report/viewer.py encode_array)
    var cut = text.indexOf(':'), bin = atob(text.slice(cut + 1)), bytes = new Uint8Array(bin.length);
    for (var i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
    return new TYPES[text.slice(0, cut)](bytes.buffer);
  }
  function ramp(t) {
    t = Math.min(Math.max(t, 0), 1) * (RAMP.length - 1);
    var i = Math.min(Math.floor(t), RAMP.length - 2), f = t - i, a = RAMP[i], b = RAMP[i + 1];
    return [a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2])];
  }
  function css(c) { return 'rgb(' + c.map(function (v) { return Math.round(255 * v); }).join(',') + ')'; }
  function hatch(c) {               // the layer's look: its colour with darker diagonal stripes
    var dark = css(c.map(function (v) { return 0.55 * v; }));
    return 'repeating-linear-gradient(45deg, ' + dark + ' 0 2px, ' + css(c) + ' 2px 6px)';
  }
  function fmt(v, digits) {
    if (v === null || v === undefined || !isFinite(v)) return '–';
    return Number(v.toPrecision(digits || 4)).toString();
  }
  function el(tag, cls, text) {
    var e = document.createElement(tag);
    if (cls) e.className = cls;
    if (text !== undefined) e.textContent = text;
    return e;
  }

  function Viewer(root) {
    var self = this;
    this.root = root;
    this.scenes = JSON.parse(root.querySelector('script.fp-scenes').textContent).scenes;
    this.pick = null;
    var bar = el('div', 'fp-bar');
    if (this.scenes.length > 1) {
      this.sceneSelect = el('select', 'fp-scene');
      this.scenes.forEach(function (s, i) { var o = el('option', '', s.title); o.value = i; self.sceneSelect.appendChild(o); });
      this.sceneSelect.onchange = function () { self.setScene(+this.value); };
      bar.appendChild(el('label', '', 'Candidate ')); bar.appendChild(this.sceneSelect);
    }
    this.modeSelect = el('select', 'fp-mode');
    this.modeSelect.onchange = function () { self.setMode(this.value); };
    bar.appendChild(el('label', '', ' Colour ')); bar.appendChild(this.modeSelect);
    bar.appendChild(el('span', '', ' View '));
    [['eye', 'eye level'], ['front', 'front'], ['above', '30° above'], ['top', 'top']].forEach(function (v) {
      var b = el('button', 'fp-view', v[1]); b.type = 'button'; b.dataset.view = v[0];
      b.onclick = function () { self.setView(v[0]); }; bar.appendChild(b);
    });
    var lab = el('label', 'fp-strips-label');
    this.stripsBox = el('input', 'fp-strips'); this.stripsBox.type = 'checkbox';
    this.stripsBox.onchange = function () { self.colourEdges(); self.render(); };
    lab.appendChild(this.stripsBox); lab.appendChild(document.createTextNode(' strips by family (A blue, B orange)'));
    bar.appendChild(lab);
    // the scene's second set of panels (boundary panels), shown unless unticked
    this.layerLabel = el('label', 'fp-layer-label');
    this.layerBox = el('input', 'fp-layer'); this.layerBox.type = 'checkbox'; this.layerBox.checked = true;
    this.layerBox.onchange = function () { self.showLayer(this.checked); };
    this.layerText = el('span', '', ''); this.layerSwatch = el('span', 'fp-swatch');
    this.layerLabel.appendChild(this.layerBox); this.layerLabel.appendChild(document.createTextNode(' '));
    this.layerLabel.appendChild(this.layerSwatch); this.layerLabel.appendChild(this.layerText);
    bar.appendChild(this.layerLabel);
    root.appendChild(bar);
    this.holder = el('div', 'fp-canvas');
    root.appendChild(this.holder);
    this.legend = el('div', 'fp-legend'); root.appendChild(this.legend);
    this.info = el('div', 'fp-info', 'Click or hover a panel for its numbers.'); root.appendChild(this.info);

    var r = this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    r.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    r.setClearColor(0xf4f5f7);
    this.holder.appendChild(r.domElement);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.01, 1e7);
    this.camera.up.set(0, 0, 1);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8a80, 1.7));
    this.light = new THREE.DirectionalLight(0xffffff, 1.4);
    this.scene.add(this.light);
    this.controls = new THREE.OrbitControls(this.camera, r.domElement);
    this.controls.addEventListener('change', function () { self.render(); });
    this.raycaster = new THREE.Raycaster();
    var down = null;
    r.domElement.addEventListener('pointerdown', function (e) { down = [e.clientX, e.clientY]; });
    r.domElement.addEventListener('pointerup', function (e) {
      if (down && Math.abs(e.clientX - down[0]) + Math.abs(e.clientY - down[1]) < 5) self.pickAt(e.clientX, e.clientY, true);
      down = null;
    });
    var pending = false;
    r.domElement.addEventListener('pointermove', function (e) {
      if (e.buttons || pending || (self.pick && self.pick.pinned)) return;
      pending = true;
      requestAnimationFrame(function () { pending = false; self.pickAt(e.clientX, e.clientY, false); });
    });
    window.addEventListener('resize', function () { self.resize(); });
    this.resize();
    if (this.scenes.length) this.setScene(0);   // (a page may bring its scene later)
    root.dataset.ready = '1';
  }

  Viewer.prototype.resize = function () {
    var w = Math.max(this.holder.clientWidth, 200), h = Math.round(Math.min(Math.max(w * 0.6, 320), 640));
    this.renderer.setSize(w, h);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  };

  Viewer.prototype.render = function () {
    if (!this.mesh) return;
    this.light.position.copy(this.camera.position);
    this.renderer.render(this.scene, this.camera);
  };

  /* show scene i; with keepView the camera stays where it is (a scene replaced by the
     same net moved, as in fabplan edit) */
  Viewer.prototype.setScene = function (i, keepView) {
    var s = this.scenes[i], self = this;
    this.index = i; this.data = s;
    if (this.sceneSelect) this.sceneSelect.value = i;
    [this.mesh, this.lines, this.gaps, this.outline, this.layerMesh, this.layerLines].forEach(function (o) {
      if (o) { self.scene.remove(o); o.geometry.dispose(); }
    });
    this.outline = null; this.pick = null;
    var P = decode(s.positions), sizes = decode(s.face_sizes);
    var idx = decode(s.face_indices), ntri = 0, f, j;
    for (f = 0; f < sizes.length; f++) ntri += sizes[f] - 2;
    var corner = new Int32Array(3 * ntri), triFace = new Int32Array(ntri), t = 0, ptr = 0;
    this.facePtr = new Int32Array(sizes.length + 1);
    for (f = 0; f < sizes.length; f++) {
      this.facePtr[f] = ptr;
      for (j = 1; j < sizes[f] - 1; j++) {
        corner[3 * t] = idx[ptr]; corner[3 * t + 1] = idx[ptr + j]; corner[3 * t + 2] = idx[ptr + j + 1];
        triFace[t++] = f;
      }
      ptr += sizes[f];
    }
    this.facePtr[sizes.length] = ptr;
    var pos = new Float32Array(9 * ntri);
    for (var c = 0; c < 3 * ntri; c++) {
      pos[3 * c] = P[3 * corner[c]]; pos[3 * c + 1] = P[3 * corner[c] + 1]; pos[3 * c + 2] = P[3 * corner[c] + 2];
    }
    this.P = P; this.faceIndices = idx; this.corner = corner; this.triFace = triFace;
    var g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    g.setAttribute('color', new THREE.BufferAttribute(new Float32Array(9 * ntri), 3));
    g.computeVertexNormals();
    g.computeBoundingSphere();
    this.mesh = new THREE.Mesh(g, new THREE.MeshLambertMaterial({
      vertexColors: true, side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 }));
    this.scene.add(this.mesh);
    var E = decode(s.edges), ne = E.length / 2, lp = new Float32Array(6 * ne);
    for (var e = 0; e < 2 * ne; e++) { lp[3 * e] = P[3 * E[e]]; lp[3 * e + 1] = P[3 * E[e] + 1]; lp[3 * e + 2] = P[3 * E[e] + 2]; }
    var lg = new THREE.BufferGeometry();
    lg.setAttribute('position', new THREE.BufferAttribute(lp, 3));
    lg.setAttribute('color', new THREE.BufferAttribute(new Float32Array(6 * ne), 3));
    this.edgeFamily = decode(s.edge_family);
    this.lines = new THREE.LineSegments(lg, new THREE.LineBasicMaterial({ vertexColors: true, transparent: true }));
    this.scene.add(this.lines);
    this.gaps = null;
    if (s.gaps) {
      var gg = new THREE.BufferGeometry();
      gg.setAttribute('position', new THREE.BufferAttribute(decode(s.gaps), 3));
      gg.computeVertexNormals();
      this.gaps = new THREE.Mesh(gg, new THREE.MeshLambertMaterial({ color: 0xd62728, side: THREE.DoubleSide }));
      this.scene.add(this.gaps);
    }
    this.infoFields = s.info.map(decodeInfo);
    this.buildLayer(s.layer);
    this.modeSelect.innerHTML = '';
    s.modes.forEach(function (m) { var o = el('option', '', m.label); o.value = m.key; self.modeSelect.appendChild(o); });
    var keep = this.mode && s.modes.some(function (m) { return m.key === self.mode; }) ? this.mode : s.modes[0].key;
    this.setMode(keep);
    this.colourEdges();
    if (keepView) this.render(); else this.setView(s.views.initial);
  };

  function decodeInfo(q) {
    return { label: q.label, unit: q.unit, digits: q.digits, integer: q.integer, names: q.names,
      absent: q.absent, values: decode(q.values) };
  }

  /* the scene's layer of extra panels (boundary panels): triangles in one colour, their
     outlines darker, picked by panel */
  Viewer.prototype.buildLayer = function (L) {
    this.layerMesh = this.layerLines = this.layer = null;
    this.layerLabel.style.display = L ? '' : 'none';
    if (!L) return;
    var P = decode(L.positions), T = decode(L.triangles), sizes = decode(L.face_sizes), idx = decode(L.face_indices);
    var pos = new Float32Array(3 * T.length), c, k, q;
    for (c = 0; c < T.length; c++) for (q = 0; q < 3; q++) pos[3 * c + q] = P[3 * T[c] + q];
    var g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(pos, 3));
    g.computeVertexNormals();
    var col = new THREE.Color(L.colour[0], L.colour[1], L.colour[2]);
    var material = new THREE.MeshLambertMaterial({ color: col, side: THREE.DoubleSide,
      polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1 });
    // hatched, so that no mold colour or colour scale can be taken for them
    material.onBeforeCompile = function (shader) {
      shader.fragmentShader = shader.fragmentShader.replace('#include <dithering_fragment>',
        '#include <dithering_fragment>\n\tif (mod(gl_FragCoord.x + gl_FragCoord.y, 8.0) < 3.0) gl_FragColor.rgb *= 0.55;');
    };
    this.layerMesh = new THREE.Mesh(g, material);
    var ptr = new Int32Array(sizes.length + 1), nseg = 0;
    for (k = 0; k < sizes.length; k++) { ptr[k + 1] = ptr[k] + sizes[k]; nseg += sizes[k]; }
    var lp = new Float32Array(6 * nseg), e = 0;
    for (k = 0; k < sizes.length; k++) for (var j = ptr[k]; j < ptr[k + 1]; j++) {
      var a = idx[j], b = idx[j + 1 < ptr[k + 1] ? j + 1 : ptr[k]];
      for (q = 0; q < 3; q++) { lp[6 * e + q] = P[3 * a + q]; lp[6 * e + 3 + q] = P[3 * b + q]; }
      e++;
    }
    var lg = new THREE.BufferGeometry();
    lg.setAttribute('position', new THREE.BufferAttribute(lp, 3));
    this.layerLines = new THREE.LineSegments(lg, new THREE.LineBasicMaterial({ color: col.clone().multiplyScalar(0.45) }));
    this.layer = { label: L.label, how: L.how, colour: L.colour, P: P, ptr: ptr, idx: idx,
      triPanel: decode(L.triangle_panel), count: sizes.length, info: L.info.map(decodeInfo) };
    this.layerSwatch.style.background = hatch(L.colour);
    this.layerText.textContent = ' ' + L.toggle;
    this.scene.add(this.layerMesh); this.scene.add(this.layerLines);
    this.showLayer(this.layerBox.checked, true);
  };

  Viewer.prototype.showLayer = function (on, quiet) {
    if (!this.layer) return;
    this.layerBox.checked = on;
    this.layerMesh.visible = this.layerLines.visible = on;
    if (!on && this.pick && this.pick.layer) { this.pick = null; this.showInfo(-1); }
    if (!quiet) { this.drawLegend(this.data.modes.filter(function (m) { return m.key === this.mode; }, this)[0]); this.render(); }
  };

  Viewer.prototype.setMode = function (key) {
    var s = this.data, m = s.modes.filter(function (x) { return x.key === key; })[0];
    this.mode = key; this.modeSelect.value = key;
    var col = this.mesh.geometry.attributes.color.array, n = this.corner.length, i, v, c;
    var values = m.values ? decode(m.values) : null;
    var palette = m.palette ? decode(m.palette) : null;
    var lo = m.range ? m.range[0] : 0, hi = m.range ? m.range[1] : 1, span = hi > lo ? hi - lo : 1;
    for (i = 0; i < n; i++) {
      if (!values) { c = PLAIN; }
      else {
        v = m.where === 'face' ? values[this.triFace[(i / 3) | 0]] : values[this.corner[i]];
        if (m.categorical) c = v >= 0 ? [palette[3 * v], palette[3 * v + 1], palette[3 * v + 2]] : NONE;
        else if (!isFinite(v)) c = NONE;
        else if (m.limit !== null && m.limit !== undefined && v > m.limit) c = OVER;
        else c = ramp((v - lo) / span);
      }
      col[3 * i] = c[0]; col[3 * i + 1] = c[1]; col[3 * i + 2] = c[2];
    }
    this.mesh.geometry.attributes.color.needsUpdate = true;
    if (this.gaps) this.gaps.visible = key === 'gaps';
    this.drawLegend(m);
    this.render();
  };

  Viewer.prototype.drawLegend = function (m) {
    var L = this.legend;
    L.innerHTML = '';
    this.drawScale(m);
    if (this.layer && this.layerBox.checked) {
      var item = el('div', 'fp-layer-how'), swatch = el('span', 'fp-swatch');
      swatch.style.background = hatch(this.layer.colour);
      item.appendChild(swatch); item.appendChild(document.createTextNode(' ' + this.layer.how));
      L.appendChild(item);
    }
  };

  Viewer.prototype.drawScale = function (m) {
    var L = this.legend;
    if (m.categorical || !m.values) { L.appendChild(el('span', 'fp-how', m.how)); return; }
    var lo = m.range[0], hi = m.range[1], scale = el('div', 'fp-scale');
    var stops = RAMP.map(function (c, i) { return css(c) + ' ' + (100 * i / (RAMP.length - 1)).toFixed(0) + '%'; });
    var limited = m.limit !== null && m.limit !== undefined && m.limit < hi;
    var at = limited ? Math.max(0, Math.min(100, 100 * (m.limit - lo) / (hi - lo))) : 100;
    scale.style.background = limited ? 'linear-gradient(to right, ' + RAMP.map(function (c, i) {
      return css(c) + ' ' + (at * i / (RAMP.length - 1)).toFixed(1) + '%'; }).join(', ') + ', ' + css(OVER) + ' ' + at.toFixed(1) + '%)'
      : 'linear-gradient(to right, ' + stops.join(', ') + ')';
    var wrap = el('div', 'fp-scale-wrap');
    wrap.appendChild(el('span', 'fp-lo', fmt(lo) + ' ' + m.unit));
    wrap.appendChild(scale);
    wrap.appendChild(el('span', 'fp-hi', fmt(hi) + ' ' + m.unit));
    if (m.limit !== null && m.limit !== undefined) {
      var mark = el('div', 'fp-limit'); mark.style.left = at + '%';
      mark.appendChild(el('span', '', 'limit ' + fmt(m.limit) + ' ' + m.unit));
      scale.appendChild(mark);
    }
    L.appendChild(wrap);
    L.appendChild(el('span', 'fp-how', m.how));
  };

  Viewer.prototype.colourEdges = function () {
    var on = this.stripsBox.checked, col = this.lines.geometry.attributes.color.array;
    for (var e = 0; e < this.edgeFamily.length; e++) {
      var fam = this.edgeFamily[e], c = on ? FAMILY[fam >= 0 && fam < 2 ? fam : 2] : [0.15, 0.15, 0.15];
      for (var k = 0; k < 2; k++) { col[6 * e + 3 * k] = c[0]; col[6 * e + 3 * k + 1] = c[1]; col[6 * e + 3 * k + 2] = c[2]; }
    }
    this.lines.material.opacity = on ? 1.0 : 0.35;
    this.lines.geometry.attributes.color.needsUpdate = true;
  };

  Viewer.prototype.setView = function (name) {
    var s = this.data, v = s.views, sphere = this.mesh.geometry.boundingSphere, R = sphere.radius;
    var c = sphere.center, fx = v.front[0], fy = v.front[1];
    var d = R / Math.sin(this.camera.fov * Math.PI / 360) * 0.85, target = c.clone(), elev;
    if (name === 'eye') {
      // a person standing in front of the design, eyes at eye height above its lowest point
      var D = d;
      this.camera.position.set(c.x + fx * D, c.y + fy * D, v.ground + v.eye_height);
    } else {
      elev = { front: 8, above: 30, top: 89.5 }[name] * Math.PI / 180;
      this.camera.position.set(c.x + d * fx * Math.cos(elev), c.y + d * fy * Math.cos(elev), c.z + d * Math.sin(elev));
    }
    this.camera.near = d / 1000; this.camera.far = d * 100;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(target);
    this.camera.lookAt(target);
    this.controls.update();
    this.view = name;
    var buttons = this.root.querySelectorAll('button.fp-view');
    for (var i = 0; i < buttons.length; i++) buttons[i].classList.toggle('fp-on', buttons[i].dataset.view === name);
    this.render();
  };

  Viewer.prototype.pickAt = function (x, y, pin) {
    var rect = this.renderer.domElement.getBoundingClientRect();
    var ndc = new THREE.Vector2(2 * (x - rect.left) / rect.width - 1, 1 - 2 * (y - rect.top) / rect.height);
    this.raycaster.setFromCamera(ndc, this.camera);
    var hit = this.raycaster.intersectObject(this.mesh, false)[0], onLayer = false;
    if (this.layer && this.layerMesh.visible) {
      var other = this.raycaster.intersectObject(this.layerMesh, false)[0];
      if (other && (!hit || other.distance < hit.distance)) { hit = other; onLayer = true; }
    }
    if (!hit) { if (pin) { this.pick = null; this.showInfo(-1); } return -1; }
    var face = onLayer ? this.layer.triPanel[hit.faceIndex] : this.triFace[hit.faceIndex];
    this.pick = { face: face, layer: onLayer, pinned: !!pin };
    this.showInfo(face, onLayer);
    return face;
  };

  Viewer.prototype.showInfo = function (face, onLayer) {
    var self = this, L = onLayer ? this.layer : null;
    if (this.outline) { this.scene.remove(this.outline); this.outline.geometry.dispose(); this.outline = null; }
    if (face < 0) { this.info.textContent = 'Click or hover a panel for its numbers.'; this.render(); return; }
    var ptr = L ? L.ptr : this.facePtr, ids = L ? L.idx : this.faceIndices, P = L ? L.P : this.P;
    var a = ptr[face], b = ptr[face + 1], pts = new Float32Array(3 * (b - a));
    for (var k = a; k < b; k++) for (var q = 0; q < 3; q++) pts[3 * (k - a) + q] = P[3 * ids[k] + q];
    var og = new THREE.BufferGeometry();
    og.setAttribute('position', new THREE.BufferAttribute(pts, 3));
    this.outline = new THREE.LineLoop(og, new THREE.LineBasicMaterial({ color: 0xffd400, depthTest: false }));
    this.outline.renderOrder = 10;
    this.scene.add(this.outline);
    this.info.innerHTML = '';
    var item = el('span', 'fp-item'); item.dataset.key = L ? 'layer' : 'face';
    item.appendChild(el('b', '', (L ? L.label : 'face') + ' ')); item.appendChild(el('span', 'fp-value', String(face)));
    this.info.appendChild(item);
    (L ? L.info : this.infoFields).forEach(function (q) {
      var v = q.values[face], it = el('span', 'fp-item');
      it.dataset.key = q.label;
      it.appendChild(el('b', '', q.label + ' '));
      var text = q.names ? (q.names[v] === undefined ? String(v) : q.names[v])
        : q.integer ? (v < 0 && q.absent ? q.absent : String(v)) : fmt(v, q.digits);
      it.appendChild(el('span', 'fp-value', text));
      if (q.unit && isFinite(v) && !q.names) it.appendChild(document.createTextNode(' ' + q.unit));
      self.info.appendChild(it);
    });
    this.render();
  };

  /* client coordinates of a face's centroid on screen (for tests and links); with
     onLayer, of a panel of the layer (a triangle's centroid: outlines may be concave) */
  Viewer.prototype.screenPointOfFace = function (face, onLayer) {
    var L = onLayer ? this.layer : null, p = new THREE.Vector3(), k;
    if (L) {
      var T = decode(this.data.layer.triangles), t = L.triPanel.indexOf(face);
      for (k = 0; k < 3; k++) p.add(new THREE.Vector3(L.P[3 * T[3 * t + k]], L.P[3 * T[3 * t + k] + 1], L.P[3 * T[3 * t + k] + 2]));
      p.multiplyScalar(1 / 3).project(this.camera);
    } else {
      var a = this.facePtr[face], b = this.facePtr[face + 1];
      for (k = a; k < b; k++) p.add(new THREE.Vector3(this.P[3 * this.faceIndices[k]], this.P[3 * this.faceIndices[k] + 1], this.P[3 * this.faceIndices[k] + 2]));
      p.multiplyScalar(1 / (b - a)).project(this.camera);
    }
    var rect = this.renderer.domElement.getBoundingClientRect();
    return { x: rect.left + (p.x + 1) / 2 * rect.width, y: rect.top + (1 - p.y) / 2 * rect.height };
  };

  function start() {
    window.fabplanViewers = [];
    var roots = document.querySelectorAll('div.fp-viewer');
    for (var i = 0; i < roots.length; i++) {
      try { window.fabplanViewers.push(new Viewer(roots[i])); }
      catch (err) {
        roots[i].appendChild(el('p', 'fail', 'The 3D view needs WebGL, which this browser does not offer here (' +
          err.message + '); the pictures below show the same.'));
      }
    }
    var links = document.querySelectorAll('a[data-fp-scene]');
    for (var j = 0; j < links.length; j++) links[j].addEventListener('click', function () {
      var v = window.fabplanViewers[0];
      if (v) v.setScene(+this.dataset.fpScene);
    });
  }
  if (document.readyState === 'loading') document.addEventListener('DOMContentLoaded', start); else start();
})();

// fractalc studio's page: the scene text, its controls, the live image and
// the timeline, talking to the studio over one WebSocket. The server holds
// the state; the page sends what the user does and shows what comes back.
// `window.studio` is the page's state (the browser tests read it).
(() => {
  "use strict";
  const { element, row, keyControls, paramControl } = window.Controls;
  const $ = (id) => document.getElementById(id);

  const TEXT_PAUSE_MS = 300;           // typing stops this long: the text is checked and built
  const VIEW_MS = 16;                  // at most one view change per display frame
  const ORBIT_RADIANS_PER_PIXEL = 0.005;
  const ZOOM_PER_WHEEL_UNIT = 0.001;
  const FLY_SPEED = 0.5;               // of the distance to the target, per second
  const FAST_FACTOR = 4;               // with Shift
  const NOTICE_MS = 6000;

  const token = new URLSearchParams(location.search).get("token") || "";
  const studio = window.studio = {
    frames: 0, lastFrame: null, seq: 0, scene: null, params: {}, camera: null, fileCamera: null,
    diagnostics: [], dirty: {}, building: false, keyframes: [], presets: {}, job: null, text: "",
    textSentAt: 0, sceneAt: 0,    // when the page last sent its text, and last had a checked scene
  };

  // ---- the connection ---------------------------------------------------------

  const socket = new WebSocket(`${location.protocol === "https:" ? "wss" : "ws"}://${location.host}/socket?token=${encodeURIComponent(token)}`);
  socket.binaryType = "arraybuffer";
  studio.socket = socket;

  function send(message) {
    if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message));
  }
  studio.send = send;

  socket.addEventListener("message", (event) => {
    if (event.data instanceof ArrayBuffer) showFrame(event.data);
    else receive(JSON.parse(event.data));
  });
  socket.addEventListener("close", () => notice("the studio is gone (stopped?): reload the page once it runs", true));

  const handlers = {
    device: (m) => { $("device").textContent = m.name; },
    text: (m) => { editor.setText(m.text); studio.text = editor.text; },
    diagnostics: (m) => showDiagnostics(m.items),
    scene: (m) => showScene(m),
    values: (m) => showValues(m),
    presets: (m) => showPresets(m.presets),
    keyframes: (m) => showKeyframes(m.times),
    status: (m) => { studio.building = m.building; updateNote(); },
    notice: (m) => notice(m.text, m.error),
    dirty: (m) => showDirty(m),
    job: (m) => showJob(m),
    disk_changed: () => { $("banner").hidden = false; },
  };

  function receive(message) {
    const handler = handlers[message.type];
    if (handler) handler(message);
  }

  // ---- the text -----------------------------------------------------------------

  let textTimer = null;
  const editor = new window.Editor($("editor"), () => {
    clearTimeout(textTimer);
    textTimer = setTimeout(sendText, TEXT_PAUSE_MS);
  });
  studio.editor = editor;

  function sendText() {
    clearTimeout(textTimer);
    textTimer = null;
    if (editor.text !== studio.text) {
      studio.text = editor.text;
      studio.textSentAt = performance.now();
      send({ type: "text", text: editor.text });
    }
  }

  function showDiagnostics(items) {
    studio.diagnostics = items;
    editor.setDiagnostics(items);
    const list = $("diagnostics");
    list.replaceChildren(...items.map((d) => {
      const item = element("li", { textContent: d.text });
      item.addEventListener("click", () => editor.focusAt(d.line, d.column));
      return item;
    }));
    updateNote();
  }

  // ---- the image ------------------------------------------------------------------

  const canvas = $("image");
  const context = canvas.getContext("2d");
  let decoding = false, waitingFrame = null, lastFrameTime = 0, frameRate = 0;

  // Frames are drawn in order; one waits while another decodes (the newest wins).
  function showFrame(buffer) {
    if (decoding) { waitingFrame = buffer; return; }
    decoding = true;
    const length = new DataView(buffer).getUint32(0);
    const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, length)));
    const jpeg = new Uint8Array(buffer, 4 + length);
    createImageBitmap(new Blob([jpeg], { type: "image/jpeg" })).then((bitmap) => {
      canvas.width = header.width;
      canvas.height = header.height;
      context.drawImage(bitmap, 0, 0);
      bitmap.close();
      const now = performance.now();
      if (lastFrameTime) frameRate = 0.8 * frameRate + 0.2 * (1000 / Math.max(1, now - lastFrameTime));
      lastFrameTime = now;
      header.digest = digest(jpeg);
      header.shownAt = now;
      studio.lastFrame = header;
      studio.frames += 1;
      studio.building = false;
      window.dispatchEvent(new Event("studioframe"));      // for tests and benchmarks: an image was drawn
      $("stats").textContent = `${frameRate.toFixed(1)} fps | ${header.width}x${header.height} | ` +
        `${header.samples} sample${header.samples === 1 ? "" : "s"} | ${header.milliseconds} ms | ${header.builds} builds`;
      updateNote();
    }).finally(() => {
      decoding = false;
      if (waitingFrame) { const next = waitingFrame; waitingFrame = null; showFrame(next); }
    });
  }

  function digest(bytes) {       // FNV-1a: tells two images apart
    let hash = 0x811c9dc5;
    for (let i = 0; i < bytes.length; i++) hash = Math.imul(hash ^ bytes[i], 16777619) >>> 0;
    return hash;
  }

  function updateNote() {
    const errors = studio.diagnostics.length;
    const text = studio.building ? "building the kernel..." :
      errors ? `${errors} error${errors > 1 ? "s" : ""} in the text: the image is of the last text that checked` : "";
    const box = $("note");
    box.hidden = !text;
    box.textContent = text;
    box.className = errors && !studio.building ? "error" : "";
  }

  // The image keeps the aspect of the file's render size, as large as the stage shows it.
  function layout() {
    const scene = studio.scene;
    if (!scene) return;
    const stage = $("stage");
    const [width, height] = scene.live_size || scene.render_size;
    const scale = Math.min(stage.clientWidth / width, stage.clientHeight / height);
    const cssWidth = Math.max(16, Math.floor(width * scale)), cssHeight = Math.max(16, Math.floor(height * scale));
    canvas.style.width = `${cssWidth}px`;
    canvas.style.height = `${cssHeight}px`;
    const ratio = window.devicePixelRatio || 1;
    const size = [Math.round(cssWidth * ratio), Math.round(cssHeight * ratio)];
    if (!studio.size || size[0] !== studio.size[0] || size[1] !== studio.size[1]) {
      studio.size = size;
      viewChanged({ size });
    }
  }
  new ResizeObserver(layout).observe($("stage"));

  // ---- the view: params and camera --------------------------------------------

  let viewTimer = null, viewPending = {}, viewSentAt = -Infinity;

  // Changes go out at most once per VIEW_MS (the newest state wins), at
  // once when the last went out longer ago.
  function viewChanged(change) {
    for (const [key, value] of Object.entries(change)) {
      viewPending[key] = key === "params" ? { ...(viewPending.params || {}), ...value } : value;
    }
    if (viewTimer === null) viewTimer = setTimeout(sendView, Math.max(0, viewSentAt + VIEW_MS - performance.now()));
  }

  function sendView() {
    viewTimer = null;
    viewSentAt = performance.now();
    studio.seq += 1;
    send({ type: "view", seq: studio.seq, ...viewPending });
    viewPending = {};
  }

  const paramRows = {};

  function showScene(scene) {
    studio.scene = scene;
    studio.sceneAt = performance.now();
    $("file").textContent = scene.file;
    const params = $("params");
    params.replaceChildren();
    for (const p of scene.params) {
      paramRows[p.name] = paramControl(p, studio.params[p.name] ?? p.default, (value) => {
        studio.params[p.name] = value;
        viewChanged({ params: { [p.name]: value } });
      });
      params.append(paramRows[p.name]);
    }
    if (!scene.params.length) params.append(element("span", { className: "disabled-note", textContent: "no params" }));
    showKeys(scene.controls);
    const stem = scene.file.replace(/\.frac$/, "");
    if (!$("output").value) $("output").value = `${stem}.png`;
    if (!$("frames-output").value) $("frames-output").value = `${stem}_frames/frame_%04d.png`;
    if (!$("final-width").value) [$("final-width").value, $("final-height").value] = scene.render_size;
    $("final-integrator").value = scene.integrator;
    studio.fileCamera = scene.camera;
    layout();
  }

  function showKeys(controls) {
    const set = (block, extra) => (path, value) => { sendText(); send({ type: "key", block, key: path, value, ...extra }); };
    const render = $("render-keys");
    render.replaceChildren();
    keyControls(render, controls.render.specs, controls.render.values, set("render", {}));
    const lights = $("lights");
    lights.replaceChildren();
    controls.lights.forEach((light, index) => {
      const group = element("div", { className: "group" }, [element("div", { className: "title", textContent: `light ${index + 1}: ${light.kind}` })]);
      keyControls(group, light.specs, light.values, set("light", { index }));
      lights.append(group);
    });
    if (!controls.lights.length) lights.append(element("span", { className: "disabled-note", textContent: "no lights: a headlight" }));
    const materials = $("materials");
    materials.replaceChildren();
    for (const material of controls.materials) {
      const group = element("div", { className: "group" }, [element("div", { className: "title", textContent: material.name })]);
      keyControls(group, material.specs, material.values, set("material", { name: material.name }), true);
      materials.append(group);
    }
    if (!controls.materials.length) materials.append(element("span", { className: "disabled-note", textContent: "no materials declared" }));
  }

  function showValues(values) {
    studio.params = { ...values.params };
    for (const [name, value] of Object.entries(values.params)) if (paramRows[name]) paramRows[name].show(value);
    studio.camera = values.camera;
    showCamera();
    setTime(values.time, false);
  }

  function showCamera() {
    const c = studio.camera;
    if (!c) return;
    const v = (x) => `(${x.map((n) => n.toFixed(3)).join(", ")})`;
    $("camera").textContent = `position ${v(c.position)}\ntarget   ${v(c.target)}\nfov      ${c.fov.toFixed(2)}`;
  }

  // camera arithmetic on 3-vectors
  const add = (a, b) => a.map((x, i) => x + b[i]);
  const sub = (a, b) => a.map((x, i) => x - b[i]);
  const scale = (a, s) => a.map((x) => x * s);
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => Math.hypot(...a);
  const unit = (a) => scale(a, 1 / (norm(a) || 1));

  function rotate(v, axis, angle) {      // Rodrigues, about a unit axis
    const c = Math.cos(angle), s = Math.sin(angle);
    return add(add(scale(v, c), scale(cross(axis, v), s)), scale(axis, dot(axis, v) * (1 - c)));
  }

  function moveCamera(change) {
    studio.camera = { ...studio.camera, ...change };
    showCamera();
    viewChanged({ camera: studio.camera });
  }

  function axes() {
    const c = studio.camera;
    const forward = unit(sub(c.target, c.position));
    const right = unit(cross(forward, c.up));
    return { forward, right, up: cross(right, forward) };
  }

  function orbit(dx, dy) {
    const c = studio.camera, up = unit(c.up);
    let offset = rotate(sub(c.position, c.target), up, -dx * ORBIT_RADIANS_PER_PIXEL);
    const right = unit(cross(scale(offset, -1), up));
    const turned = rotate(offset, right, -dy * ORBIT_RADIANS_PER_PIXEL);
    const elevation = Math.acos(Math.max(-1, Math.min(1, dot(unit(turned), up))));
    if (elevation > 0.03 && elevation < Math.PI - 0.03) offset = turned;     // never over the pole
    moveCamera({ position: add(c.target, offset) });
  }

  function pan(dx, dy) {
    const c = studio.camera, { right, up } = axes();
    const perPixel = 2 * norm(sub(c.position, c.target)) * Math.tan((c.fov * Math.PI) / 360) / canvas.clientHeight;
    const move = add(scale(right, -dx * perPixel), scale(up, dy * perPixel));
    moveCamera({ position: add(c.position, move), target: add(c.target, move) });
  }

  function zoom(amount) {
    const c = studio.camera;
    const offset = scale(sub(c.position, c.target), Math.exp(amount * ZOOM_PER_WHEEL_UNIT));
    if (norm(offset) > 1e-6) moveCamera({ position: add(c.target, offset) });
  }

  let dragging = null;
  canvas.addEventListener("contextmenu", (event) => event.preventDefault());
  canvas.addEventListener("pointerdown", (event) => {
    if (!studio.camera) return;
    canvas.focus();
    canvas.setPointerCapture(event.pointerId);
    dragging = { x: event.clientX, y: event.clientY, pan: event.button === 2 || event.shiftKey };
  });
  canvas.addEventListener("pointermove", (event) => {
    if (!dragging) return;
    const dx = event.clientX - dragging.x, dy = event.clientY - dragging.y;
    dragging.x = event.clientX;
    dragging.y = event.clientY;
    if (dragging.pan) pan(dx, dy); else orbit(dx, dy);
  });
  canvas.addEventListener("pointerup", () => { dragging = null; });
  canvas.addEventListener("wheel", (event) => {
    if (!studio.camera) return;
    event.preventDefault();
    const amount = event.deltaY || event.deltaX;     // Shift+wheel scrolls sideways in some browsers
    if (event.shiftKey || event.altKey) {
      moveCamera({ fov: Math.min(170, Math.max(1, studio.camera.fov * Math.exp(amount * ZOOM_PER_WHEEL_UNIT))) });
    } else zoom(amount);
  }, { passive: false });

  const FLY_KEYS = { w: ["forward", 1], s: ["forward", -1], d: ["right", 1], a: ["right", -1], e: ["up", 1], q: ["up", -1] };
  const held = new Set();
  let flying = null, shifted = false;
  canvas.addEventListener("keydown", (event) => {
    const key = event.key.toLowerCase();
    shifted = event.shiftKey;
    if (key in FLY_KEYS && !event.ctrlKey && !event.metaKey) {
      held.add(key);
      if (flying === null) { flying = performance.now(); requestAnimationFrame(fly); }
    } else if (key === "r") send({ type: "camera_reset" });
  });
  canvas.addEventListener("keyup", (event) => { shifted = event.shiftKey; held.delete(event.key.toLowerCase()); });
  canvas.addEventListener("blur", () => held.clear());

  function fly(now) {
    if (!held.size || !studio.camera) { flying = null; return; }
    const seconds = Math.min(0.1, (now - flying) / 1000);
    flying = now;
    const c = studio.camera, directions = axes();
    let move = [0, 0, 0];
    for (const key of held) move = add(move, scale(directions[FLY_KEYS[key][0]], FLY_KEYS[key][1]));
    const speed = FLY_SPEED * (shifted ? FAST_FACTOR : 1) * norm(sub(c.target, c.position)) * seconds;
    move = scale(move, speed);
    moveCamera({ position: add(c.position, move), target: add(c.target, move) });
    requestAnimationFrame(fly);
  }

  $("camera-reset").addEventListener("click", () => send({ type: "camera_reset" }));

  // ---- presets ------------------------------------------------------------------

  function showPresets(presets) {
    studio.presets = presets;
    const select = $("presets");
    select.replaceChildren(element("option", { value: "", textContent: "(choose a preset)" }),
      ...Object.keys(presets).map((name) => element("option", { value: name, textContent: name })));
  }
  $("presets").addEventListener("change", (event) => {
    if (event.target.value) send({ type: "preset_apply", name: event.target.value });
  });
  $("preset-save").addEventListener("click", () => {
    const name = $("preset-name").value.trim();
    if (name) send({ type: "preset_save", name });
  });

  // ---- the timeline ---------------------------------------------------------------

  let playing = null;

  function showKeyframes(times) {
    studio.keyframes = times;
    const end = times.length ? times[times.length - 1] : 0;
    $("time").max = Math.max(10, Math.ceil(end + 1));
    const max = Number($("time").max);
    $("ticks").replaceChildren(...times.map((t) => {
      const tick = element("span", { title: `keyframe at ${t}` });
      tick.style.left = `${(100 * t) / max}%`;
      return tick;
    }));
  }

  function setTime(time, scrub) {
    $("time").value = time;
    $("time-value").value = Number(time).toFixed(2);
    if (scrub) send({ type: "scrub", time: Number(time) });
  }

  $("time").addEventListener("input", () => setTime($("time").value, true));
  $("time-value").addEventListener("change", () => setTime(Math.max(0, Number($("time-value").value) || 0), true));
  $("key-add").addEventListener("click", () => send({ type: "keyframe_add", time: Number($("time").value) }));
  $("key-delete").addEventListener("click", () => {
    const time = Number($("time").value);
    const nearest = studio.keyframes.reduce((a, b) => (Math.abs(b - time) < Math.abs(a - time) ? b : a), Infinity);
    if (Math.abs(nearest - time) <= 0.05 * Number($("time").max)) send({ type: "keyframe_delete", time: nearest });
  });
  $("play").addEventListener("click", () => {
    if (playing !== null) { playing = null; $("play").textContent = "Play"; return; }
    const times = studio.keyframes;
    if (times.length < 2) { notice("the timeline needs two keyframes to play", true); return; }
    let time = Number($("time").value);
    if (time >= times[times.length - 1]) time = times[0];
    playing = performance.now();
    $("play").textContent = "Stop";
    const step = (now) => {
      if (playing === null) return;
      time += (now - playing) / 1000;
      playing = now;
      const end = times[times.length - 1];
      setTime(Math.min(time, end), true);
      if (time >= end) { playing = null; $("play").textContent = "Play"; return; }
      requestAnimationFrame(step);
    };
    requestAnimationFrame(step);
  });

  // ---- saving, the file on disk ---------------------------------------------------

  function save() { sendText(); send({ type: "save" }); }
  $("save").addEventListener("click", save);
  document.addEventListener("keydown", (event) => {
    if ((event.ctrlKey || event.metaKey) && event.key.toLowerCase() === "s") { event.preventDefault(); save(); }
  });
  $("reload").addEventListener("click", () => { $("banner").hidden = true; send({ type: "reload" }); });
  $("keep").addEventListener("click", () => { $("banner").hidden = true; send({ type: "keep" }); });

  function showDirty(dirty) {
    studio.dirty = dirty;
    const what = Object.entries(dirty).filter(([key, value]) => value && key !== "type").map(([key]) => key);
    $("unsaved").hidden = !what.length;
    $("unsaved").textContent = `unsaved: ${what.join(", ")}`;
    $("render-unsaved").hidden = !(dirty.text || dirty.presets || dirty.keyframes);
  }

  let noticeTimer = null;
  studio.notices = [];        // the last few, for the tests

  function notice(text, error = false) {
    studio.notices = [...studio.notices.slice(-19), { text, error }];
    const box = $("notice");
    box.textContent = text;
    box.title = text;
    box.className = error ? "error" : "";
    clearTimeout(noticeTimer);
    noticeTimer = setTimeout(() => { box.textContent = ""; }, NOTICE_MS);
  }
  // ---- final renders -------------------------------------------------------------

  function requestRender(kind) {
    sendText();
    send({ type: "render", kind, output: $(kind === "still" ? "output" : "frames-output").value,
      width: Number($("final-width").value), height: Number($("final-height").value),
      samples: Number($("final-samples").value), integrator: $("final-integrator").value, fps: Number($("final-fps").value) });
  }
  $("render-still").addEventListener("click", () => requestRender("still"));
  $("render-animation").addEventListener("click", () => requestRender("animation"));
  $("render-cancel").addEventListener("click", () => send({ type: "cancel" }));

  function showJob(job) {
    studio.job = job;
    const running = job.state === "running";
    $("render-cancel").disabled = !running;
    $("render-still").disabled = $("render-animation").disabled = running;
    $("render-progress").value = job.progress;
    $("render-message").textContent = running ? `rendering ${job.output}: ${Math.round(job.progress * 100)}%` : job.message;
    $("render-message").className = job.state === "failed" ? "error" : "";
    $("render-command").textContent = job.command;
  }
})();

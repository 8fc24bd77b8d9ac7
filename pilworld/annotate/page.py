"""The judges' page of the annotation app: one self-contained HTML string (inline CSS and vanilla JS).

The backend serves :func:`app_html` at ``GET /``. The page knows nothing but what the judge's API gives it
(``/api/me``, ``/api/queue``, ``/api/items/<id>``, ``PUT /api/items/<id>/label``, ``/media/...``), so it cannot
reveal an episode's origin or checkpoint: the queue shows an item's number in the judge's own order and a
done tick, the item view its instruction, its camera views and the judge's own label. All text from the API is
put into the page with ``textContent``, never as HTML. Nothing is loaded from elsewhere (the app's CSP is
``default-src 'self'`` with inline scripts and styles allowed).

Element ids are stable (the end-to-end test and ``docs/annotate_page.md`` use them): ``#judge``, ``#progress``,
``#progress-bar``, ``#queue``, ``#item-title``, ``#instruction``, ``#views`` (one ``video`` per view,
``#video-<view>``), ``#play``, ``#step-back``, ``#step-fwd``, ``#rate``, ``#scrub``, ``#frame``, ``#success``,
``#failure``, ``#mark``, ``#mark-value``, ``#goto-mark``, ``#clear-mark``, ``#category``, ``#save``, ``#prev``,
``#next``, ``#error``, ``#status``, ``#all-done``, ``#signed-out``.
"""

from __future__ import annotations

_CSS = r"""
:root {
  --bg: #f5f6f8; --panel: #ffffff; --ink: #1b1f24; --muted: #57606a; --line: #d0d7de;
  --accent: #0b57d0; --accent-ink: #ffffff; --ok: #1a7f37; --bad: #b42318; --focus: #f59e0b;
}
* { box-sizing: border-box; }
html, body { height: 100%; }
body {
  margin: 0; background: var(--bg); color: var(--ink);
  font: 14px/1.4 system-ui, -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
}
:focus-visible { outline: 3px solid var(--focus); outline-offset: 2px; }
.sr-only {
  position: absolute; width: 1px; height: 1px; padding: 0; margin: -1px; overflow: hidden;
  clip: rect(0 0 0 0); white-space: nowrap; border: 0;
}
header {
  height: 52px; display: flex; align-items: center; gap: 16px; padding: 0 16px;
  background: #1f2937; color: #f9fafb;
}
header h1 { font-size: 16px; margin: 0; font-weight: 600; }
#judge { font-weight: 600; padding: 2px 8px; border-radius: 4px; background: #374151; }
.progress-wrap { margin-left: auto; display: flex; align-items: center; gap: 10px; }
#progress-bar { width: 220px; height: 12px; accent-color: #22c55e; }
.layout { display: grid; grid-template-columns: 168px 1fr; height: calc(100% - 52px); }
nav.queue {
  border-right: 1px solid var(--line); background: var(--panel); overflow-y: auto; padding: 8px 6px;
}
nav.queue h2 {
  font-size: 12px; text-transform: uppercase; letter-spacing: .05em; color: var(--muted); margin: 4px 6px 8px;
}
#queue { list-style: none; margin: 0; padding: 0; }
#queue li { margin: 0 0 2px; }
#queue button {
  width: 100%; display: flex; justify-content: space-between; align-items: center;
  padding: 6px 10px; border: 1px solid transparent; border-radius: 6px; background: transparent;
  color: var(--ink); font: inherit; cursor: pointer; text-align: left;
}
#queue button:hover { background: #eef2f7; }
#queue button[aria-current="true"] { background: #dbe7fb; border-color: #9bb8ee; font-weight: 600; }
#queue .tick { color: var(--ok); font-weight: 700; }
main { overflow-y: auto; padding: 10px 16px 16px; }
.item-head { display: flex; align-items: baseline; gap: 14px; flex-wrap: wrap; margin-bottom: 8px; }
.item-head h2 { font-size: 18px; margin: 0; }
#instruction { font-size: 15px; margin: 0; }
#instruction::before { content: "Instruction: "; color: var(--muted); }
#all-done {
  margin: 0 0 8px; padding: 8px 12px; border-radius: 6px; background: #dcfce7; color: #14532d;
  border: 1px solid #86efac;
}
#views { display: grid; grid-template-columns: repeat(auto-fit, minmax(200px, 1fr)); gap: 8px; }
#views figure { margin: 0; background: #111827; border-radius: 6px; overflow: hidden; position: relative; }
#views video { display: block; width: 100%; height: 44vh; max-height: 420px; object-fit: contain; background: #111827; }
#views figcaption {
  position: absolute; left: 6px; top: 6px; padding: 1px 6px; border-radius: 4px;
  background: rgba(0, 0, 0, .6); color: #fff; font-size: 12px;
}
.transport {
  display: flex; align-items: center; gap: 8px; margin: 8px 0 10px; padding: 8px 10px;
  background: var(--panel); border: 1px solid var(--line); border-radius: 6px;
}
.transport label { color: var(--muted); }
#scrub { flex: 1; min-width: 200px; accent-color: var(--accent); height: 24px; }
.frame-readout { font-variant-numeric: tabular-nums; min-width: 120px; text-align: right; }
#frame { font-weight: 700; }
button, select { font: inherit; }
button.btn, select {
  padding: 5px 12px; border: 1px solid var(--line); border-radius: 6px; background: #fff; color: var(--ink);
  cursor: pointer;
}
button.btn:hover { background: #f1f4f8; }
button.btn:disabled, select:disabled { opacity: .5; cursor: not-allowed; }
button.primary { background: var(--accent); border-color: var(--accent); color: var(--accent-ink); font-weight: 600; }
button.primary:hover { background: #0842a0; }
#play { min-width: 84px; }
form#label-form {
  display: flex; flex-wrap: wrap; gap: 12px; align-items: stretch;
  background: var(--panel); border: 1px solid var(--line); border-radius: 6px; padding: 10px 12px;
}
fieldset { border: 1px solid var(--line); border-radius: 6px; margin: 0; padding: 6px 12px 10px; }
legend { font-weight: 600; padding: 0 4px; }
.radio-row { display: flex; gap: 16px; margin-top: 4px; }
.radio-row label { display: flex; align-items: center; gap: 6px; cursor: pointer; padding: 2px 4px; }
.radio-row input { width: 16px; height: 16px; accent-color: var(--accent); }
.hall-row { display: flex; align-items: center; gap: 8px; flex-wrap: wrap; margin-top: 4px; }
#mark-value { font-weight: 700; min-width: 80px; display: inline-block; }
#mark-value[data-marked="1"] { color: var(--bad); }
#category:required:invalid { border-color: var(--bad); }
.actions { display: flex; flex-direction: column; justify-content: space-between; gap: 8px; margin-left: auto; }
.actions .row { display: flex; gap: 8px; align-items: center; }
.dirty { color: #9a3412; font-style: italic; }
.messages { min-height: 22px; margin-top: 8px; }
#error { color: var(--bad); font-weight: 600; white-space: pre-wrap; }
#status { color: var(--ok); }
#signed-out {
  max-width: 560px; margin: 80px auto; padding: 20px 24px; background: var(--panel);
  border: 1px solid var(--line); border-radius: 8px;
}
kbd {
  border: 1px solid var(--line); border-bottom-width: 2px; border-radius: 3px; padding: 0 4px; font-size: 12px;
  background: #fafafa;
}
.keys { color: var(--muted); font-size: 12px; margin-top: 6px; }
"""

_BODY = r"""
<header>
  <h1>PiL-World annotation</h1>
  <span>Judge: <span id="judge">…</span></span>
  <div class="progress-wrap">
    <span id="progress" aria-live="polite">… of … labelled</span>
    <progress id="progress-bar" max="1" value="0" aria-labelledby="progress"></progress>
  </div>
</header>
<div id="signed-out" hidden role="alert">
  <h2>Not signed in</h2>
  <p id="signed-out-text">Open the sign-in link with your token that the organiser gave you, then come back to
    this page.</p>
</div>
<div class="layout" id="app">
  <nav class="queue" aria-labelledby="queue-title">
    <h2 id="queue-title">Your items</h2>
    <ol id="queue"></ol>
  </nav>
  <main>
    <p id="all-done" hidden role="status"></p>
    <div class="item-head">
      <h2 id="item-title">Loading…</h2>
      <p id="instruction"></p>
    </div>
    <section id="views" aria-label="Camera views"></section>
    <div class="transport" role="group" aria-label="Playback">
      <button type="button" class="btn" id="play" aria-keyshortcuts="Space">&#9654; Play</button>
      <button type="button" class="btn" id="step-back" aria-label="Previous frame"
        aria-keyshortcuts="ArrowLeft">&#9664;&#9664;</button>
      <button type="button" class="btn" id="step-fwd" aria-label="Next frame"
        aria-keyshortcuts="ArrowRight">&#9654;&#9654;</button>
      <label for="scrub">Frame</label>
      <input type="range" id="scrub" min="0" max="0" step="1" value="0">
      <span class="frame-readout" aria-live="off">frame
        <output id="frame" for="scrub" aria-label="Current frame">0</output> / <span id="frame-last">0</span></span>
      <label for="rate">Speed</label>
      <select id="rate">
        <option value="0.25">0.25×</option>
        <option value="0.5">0.5×</option>
        <option value="1" selected>1×</option>
        <option value="2">2×</option>
      </select>
    </div>
    <form id="label-form" novalidate>
      <fieldset>
        <legend>Outcome</legend>
        <div class="radio-row">
          <label for="success"><input type="radio" name="outcome" id="success" value="success"> Success</label>
          <label for="failure"><input type="radio" name="outcome" id="failure" value="failure"> Failure</label>
        </div>
      </fieldset>
      <fieldset>
        <legend>First obvious hallucination</legend>
        <div class="hall-row">
          <span id="mark-label">Frame:</span>
          <output id="mark-value" aria-labelledby="mark-label" data-marked="0">none</output>
          <button type="button" class="btn" id="mark" aria-keyshortcuts="M">Mark this frame</button>
          <button type="button" class="btn" id="goto-mark" disabled>Go to it</button>
          <button type="button" class="btn" id="clear-mark" disabled>Clear</button>
        </div>
        <div class="hall-row">
          <label for="category">Category</label>
          <select id="category" disabled aria-describedby="category-help">
            <option value="">— choose —</option>
          </select>
          <span id="category-help" class="sr-only">Required when a frame is marked.</span>
        </div>
      </fieldset>
      <div class="actions">
        <div class="row">
          <button type="submit" class="btn primary" id="save">Save label</button>
          <span id="dirty" class="dirty" hidden>unsaved changes</span>
        </div>
        <div class="row">
          <button type="button" class="btn" id="prev">&larr; Previous item</button>
          <button type="button" class="btn" id="next">Next item &rarr;</button>
        </div>
      </div>
    </form>
    <div class="messages">
      <div id="error" role="alert"></div>
      <div id="status" role="status"></div>
    </div>
    <p class="keys">Keys: <kbd>Space</kbd> play/pause · <kbd>&larr;</kbd>/<kbd>&rarr;</kbd> one frame
      (<kbd>Shift</kbd> ten) · <kbd>M</kbd> mark this frame · <kbd>S</kbd> success · <kbd>F</kbd> failure.
      Not while the category or speed list has the focus.</p>
  </main>
</div>
"""

_JS = r"""
(function () {
  'use strict';
  function $(id) { return document.getElementById(id); }

  var S = {
    queue: [],        // [{id, done}] in this judge's order
    index: -1,        // position of the current item in queue
    item: null,       // the current item as the API gave it
    frame: 0,
    marked: null,     // marked frame or null
    playing: false,
    saving: false,
    loadSeq: 0,
    drafts: {},       // item id -> unsaved form state, kept while the judge looks at other items
    done: 0,
    total: 0
  };
  var videos = [];

  function AuthError(message) { this.message = message; }

  async function api(method, url, body) {
    var opts = { method: method, headers: { 'Accept': 'application/json' } };
    if (body !== undefined) {
      opts.headers['Content-Type'] = 'application/json';
      opts.body = JSON.stringify(body);
    }
    var r = await fetch(url, opts);
    var text = await r.text();
    var data = null;
    try { data = text ? JSON.parse(text) : null; } catch (e) { data = null; }
    if (r.status === 401) {
      signedOut(data && typeof data.error === 'string' ? data.error : null);
      throw new AuthError('not signed in');
    }
    if (!r.ok) {
      var msg = (data && typeof data.error === 'string') ? data.error
        : ('HTTP ' + r.status + (text ? ': ' + text.slice(0, 300) : ''));
      throw new Error(msg);
    }
    return data;
  }

  function signedOut(message) {
    $('app').hidden = true;
    $('signed-out').hidden = false;
    if (message) { $('signed-out-text').textContent = message + ' — open the sign-in link with your token again.'; }
    pauseAll();
  }

  function showError(msg) { $('error').textContent = msg || ''; if (msg) { $('status').textContent = ''; } }
  function showStatus(msg) { $('status').textContent = msg || ''; }
  function fail(e) {
    if (e instanceof AuthError) { return; }
    showError(e && e.message ? e.message : String(e));
  }

  // ---------------------------------------------------------------- progress and queue
  function setProgress(done, total) {
    S.done = done; S.total = total;
    $('progress').textContent = done + ' of ' + total + ' labelled';
    var bar = $('progress-bar');
    bar.max = Math.max(total, 1);
    bar.value = done;
    var all = total > 0 && done >= total;
    var banner = $('all-done');
    banner.hidden = !all;
    banner.textContent = all ? 'All ' + total + ' items labelled — thank you. You can still revise any of them.' : '';
  }

  function renderQueue() {
    var ol = $('queue');
    ol.textContent = '';
    S.queue.forEach(function (q, i) {
      var li = document.createElement('li');
      var b = document.createElement('button');
      b.type = 'button';
      b.id = 'queue-item-' + (i + 1);
      b.dataset.index = String(i);
      b.dataset.done = q.done ? '1' : '0';
      var name = document.createElement('span');
      name.textContent = 'Item ' + (i + 1);
      var tick = document.createElement('span');
      tick.className = 'tick';
      tick.setAttribute('aria-hidden', 'true');
      tick.textContent = q.done ? '✓' : '';
      var sr = document.createElement('span');
      sr.className = 'sr-only';
      sr.textContent = q.done ? ', labelled' : ', not labelled';
      b.appendChild(name); b.appendChild(tick); b.appendChild(sr);
      if (i === S.index) { b.setAttribute('aria-current', 'true'); }
      b.addEventListener('click', function () { openItem(i); });
      li.appendChild(b);
      ol.appendChild(li);
    });
  }

  function nextUnlabelled(from) {
    var n = S.queue.length;
    for (var k = 1; k <= n; k++) {
      var j = (from + k) % n;
      if (!S.queue[j].done) { return j; }
    }
    return -1;
  }

  // ---------------------------------------------------------------- videos in sync
  function fps() { return S.item ? S.item.fps : 1; }
  function lastFrame() { return S.item ? Math.max(S.item.num_frames - 1, 0) : 0; }
  function clampFrame(f) { return Math.min(Math.max(Math.round(f), 0), lastFrame()); }
  function frameAt(t) { return Math.min(Math.max(Math.floor(t * fps() + 1e-6), 0), lastFrame()); }
  function timeOf(f) { return (f + 0.5) / fps(); }

  function showFrame(f) {
    S.frame = f;
    var scrub = $('scrub');
    scrub.value = String(f);
    scrub.setAttribute('aria-valuetext', 'frame ' + f + ' of ' + lastFrame());
    $('frame').textContent = String(f);
  }

  function seekAll(f) {
    f = clampFrame(f);
    var t = timeOf(f);
    videos.forEach(function (v) { v.currentTime = t; });
    showFrame(f);
  }

  function pauseAll() {
    S.playing = false;
    videos.forEach(function (v) { v.pause(); });
    $('play').innerHTML = '&#9654; Play';
    $('play').setAttribute('aria-pressed', 'false');
  }

  function pause() {
    if (!S.playing) { return; }
    var t = videos.length ? videos[0].currentTime : timeOf(S.frame);
    pauseAll();
    seekAll(frameAt(t));  // every view shows exactly the same frame
  }

  function play() {
    if (!S.item || !videos.length || S.playing) { return; }
    if (S.frame >= lastFrame()) { seekAll(0); }
    var t = timeOf(S.frame);
    var rate = parseFloat($('rate').value) || 1;
    S.playing = true;
    $('play').innerHTML = '&#10074;&#10074; Pause';
    $('play').setAttribute('aria-pressed', 'true');
    videos.forEach(function (v) {
      v.playbackRate = rate;
      if (Math.abs(v.currentTime - t) > 0.25 / fps()) { v.currentTime = t; }
      var p = v.play();
      if (p && p.catch) {
        p.catch(function (e) {
          if (e && e.name === 'AbortError') { return; }
          pause();
          showError('Could not play ' + (v.dataset.view || 'a view') + ': ' + (e && e.message ? e.message : e));
        });
      }
    });
    requestAnimationFrame(tick);
  }

  function togglePlay() { if (S.playing) { pause(); } else { play(); } }

  function tick() {
    if (!S.playing || !videos.length) { return; }
    var master = videos[0];
    var t = master.currentTime;
    showFrame(frameAt(t));
    if (master.ended || (master.paused && !master.seeking)) {
      pauseAll();
      seekAll(master.ended ? lastFrame() : frameAt(t));
      return;
    }
    var tol = 1 / fps();
    for (var i = 1; i < videos.length; i++) {
      var v = videos[i];
      if (!v.seeking && Math.abs(v.currentTime - t) > tol) { v.currentTime = t; }
    }
    requestAnimationFrame(tick);
  }

  function step(delta) {
    if (!S.item) { return; }
    if (S.playing) { pause(); }
    seekAll(S.frame + delta);
  }

  function clearVideos() {
    pauseAll();
    videos.forEach(function (v) { v.removeAttribute('src'); v.load(); });
    videos = [];
    $('views').textContent = '';
  }

  var MEDIA_ERRORS = { 1: 'aborted', 2: 'network error', 3: 'could not decode', 4: 'format not supported' };

  function buildVideos(item) {
    clearVideos();
    var box = $('views');
    item.views.forEach(function (view) {
      var fig = document.createElement('figure');
      var v = document.createElement('video');
      v.id = 'video-' + view;
      v.dataset.view = view;
      v.muted = true;
      v.playsInline = true;
      v.preload = 'auto';
      v.disablePictureInPicture = true;
      v.setAttribute('aria-label', 'Camera view ' + view);
      v.addEventListener('error', function () {
        var code = v.error ? v.error.code : 0;
        showError('Video ' + view + ' could not be loaded (' + (MEDIA_ERRORS[code] || 'error') + ').');
      });
      v.addEventListener('loadeddata', function () { fig.dataset.ready = '1'; });
      v.src = item.media[view];
      v.currentTime = timeOf(S.frame);
      var cap = document.createElement('figcaption');
      cap.textContent = view;
      fig.appendChild(v);
      fig.appendChild(cap);
      box.appendChild(fig);
      videos.push(v);
    });
  }

  // ---------------------------------------------------------------- label form
  function setMark(f) {
    S.marked = f;
    var out = $('mark-value');
    var cat = $('category');
    if (f === null) {
      out.textContent = 'none';
      out.dataset.marked = '0';
      cat.value = '';
      cat.disabled = true;
      cat.required = false;
    } else {
      out.textContent = 'frame ' + f;
      out.dataset.marked = '1';
      cat.disabled = false;
      cat.required = true;
    }
    $('clear-mark').disabled = f === null;
    $('goto-mark').disabled = f === null;
  }

  function fillCategories(cats) {
    var sel = $('category');
    while (sel.options.length > 1) { sel.remove(1); }
    cats.forEach(function (c) {
      var o = document.createElement('option');
      o.value = c;
      o.textContent = c;
      sel.appendChild(o);
    });
  }

  function fillForm(label) {
    $('success').checked = !!(label && label.success === true);
    $('failure').checked = !!(label && label.success === false);
    var f = label && typeof label.first_hallucination_frame === 'number' ? label.first_hallucination_frame : null;
    setMark(f);
    if (f !== null && label.category) { $('category').value = label.category; }
  }

  function formState() {
    var ok = $('success').checked, bad = $('failure').checked;
    return {
      success: ok ? true : (bad ? false : null),
      first_hallucination_frame: S.marked,
      category: S.marked === null ? null : ($('category').value || null)
    };
  }

  function sameLabel(a, b) {
    var x = a || { success: null, first_hallucination_frame: null, category: null };
    var y = b || { success: null, first_hallucination_frame: null, category: null };
    return x.success === y.success && x.first_hallucination_frame === y.first_hallucination_frame &&
      (x.category || null) === (y.category || null);
  }

  function isDirty() { return !!S.item && !sameLabel(formState(), S.item.label); }

  function updateDirty() {
    var dirty = isDirty();
    $('dirty').hidden = !dirty;
    document.body.dataset.dirty = dirty ? '1' : '0';
  }

  function keepDraft() {
    if (!S.item) { return; }
    if (isDirty()) { S.drafts[S.item.id] = formState(); } else { delete S.drafts[S.item.id]; }
  }

  async function save() {
    if (!S.item || S.saving || document.body.dataset.loading) { return; }  // never while another item loads
    showError(''); showStatus('');
    var ok = $('success').checked, bad = $('failure').checked;
    if (!ok && !bad) { showError('Choose Success or Failure first.'); $('success').focus(); return; }
    var cat = $('category').value;
    if (S.marked !== null && !cat) {
      showError('Choose the category of the hallucination at frame ' + S.marked + ' (or clear the mark).');
      $('category').focus();
      return;
    }
    var body = {
      success: ok,
      first_hallucination_frame: S.marked,
      category: S.marked === null ? null : cat
    };
    var item = S.item, index = S.index;
    S.saving = true;
    $('save').disabled = true;
    try {
      var res = await api('PUT', '/api/items/' + encodeURIComponent(item.id) + '/label', body);
      item.label = body;
      delete S.drafts[item.id];
      S.queue[index].done = true;
      updateDirty();
      setProgress(res.done, res.total);
      var next = nextUnlabelled(index);
      if (next >= 0 && next !== index) {
        await openItem(next);
        showStatus('Saved item ' + (index + 1) + '.');
      } else {
        renderQueue();
        showStatus('Saved item ' + (index + 1) + '.');
      }
    } catch (e) {
      fail(e);
    } finally {
      S.saving = false;
      $('save').disabled = false;
    }
  }

  // ---------------------------------------------------------------- items
  async function openItem(i) {
    if (i < 0 || i >= S.queue.length) { return; }
    var seq = ++S.loadSeq;
    pauseAll();
    keepDraft();
    S.index = i;
    renderQueue();
    showError(''); showStatus('');
    $('item-title').textContent = 'Item ' + (i + 1) + ' of ' + S.queue.length;
    document.body.dataset.loading = '1';
    try {
      var item = await api('GET', '/api/items/' + encodeURIComponent(S.queue[i].id));
      if (seq !== S.loadSeq) { return; }
      S.item = item;
      S.frame = 0;
      $('instruction').textContent = item.instruction;
      var scrub = $('scrub');
      scrub.max = String(lastFrame());
      $('frame-last').textContent = String(lastFrame());
      fillCategories(item.categories || []);
      var draft = S.drafts[item.id];
      fillForm(draft || item.label);
      updateDirty();
      buildVideos(item);
      showFrame(0);
      $('prev').disabled = i === 0;
      $('next').disabled = i === S.queue.length - 1;
      history.replaceState(null, '', '#item-' + (i + 1));
      if (draft) { showStatus('Your unsaved changes to this item are back; press Save to keep them.'); }
      document.body.dataset.item = String(i + 1);
    } catch (e) {
      if (seq === S.loadSeq) { fail(e); }
    } finally {
      if (seq === S.loadSeq) { delete document.body.dataset.loading; }
    }
  }

  // ---------------------------------------------------------------- keys
  function onKey(e) {
    if (e.altKey || e.ctrlKey || e.metaKey || !S.item) { return; }
    var t = e.target, tag = t && t.tagName ? t.tagName : '';
    var type = tag === 'INPUT' ? (t.type || '') : '';
    if (tag === 'SELECT' || tag === 'TEXTAREA' || (tag === 'INPUT' && type !== 'range' && type !== 'radio')) { return; }
    var k = e.key;
    if (k === 'ArrowLeft' || k === 'ArrowRight') {
      e.preventDefault();  // also on the scrubber and the radios: arrows always step frames
      step((k === 'ArrowLeft' ? -1 : 1) * (e.shiftKey ? 10 : 1));
    } else if (k === ' ' || k === 'Spacebar') {
      e.preventDefault();  // also on buttons and radios (Enter still presses a focused button)
      togglePlay();
    } else if (k === 'm' || k === 'M') {
      e.preventDefault(); markHere();
    } else if (k === 's' || k === 'S') {
      e.preventDefault(); $('success').checked = true; updateDirty();
    } else if (k === 'f' || k === 'F') {
      e.preventDefault(); $('failure').checked = true; updateDirty();
    }
  }

  function markHere() {
    if (!S.item) { return; }
    if (S.playing) { pause(); }
    setMark(S.frame);
    updateDirty();
  }

  // ---------------------------------------------------------------- wiring
  $('play').addEventListener('click', togglePlay);
  $('step-back').addEventListener('click', function () { step(-1); });
  $('step-fwd').addEventListener('click', function () { step(1); });
  $('scrub').addEventListener('input', function () {
    if (S.playing) { pauseAll(); }
    seekAll(parseInt($('scrub').value, 10) || 0);
  });
  $('rate').addEventListener('change', function () {
    var r = parseFloat($('rate').value) || 1;
    videos.forEach(function (v) { v.playbackRate = r; });
  });
  $('mark').addEventListener('click', function () { showError(''); showStatus(''); markHere(); });
  $('clear-mark').addEventListener('click', function () {
    showError(''); showStatus(''); setMark(null); updateDirty();
  });
  $('goto-mark').addEventListener('click', function () { if (S.marked !== null) { step(S.marked - S.frame); } });
  $('label-form').addEventListener('change', function () { showError(''); showStatus(''); updateDirty(); });
  window.addEventListener('beforeunload', function (e) {
    keepDraft();
    if (Object.keys(S.drafts).length) { e.preventDefault(); e.returnValue = ''; }
  });
  $('label-form').addEventListener('submit', function (e) { e.preventDefault(); save(); });
  $('prev').addEventListener('click', function () { openItem(S.index - 1); });
  $('next').addEventListener('click', function () { openItem(S.index + 1); });
  document.addEventListener('keydown', onKey);

  async function start() {
    try {
      var me = await api('GET', '/api/me');
      $('judge').textContent = me.judge;
      setProgress(me.done, me.total);
      var q = await api('GET', '/api/queue');
      S.queue = (q.items || []).map(function (x) { return { id: x.id, done: !!x.done }; });
      if (!S.queue.length) {
        $('item-title').textContent = 'No items to label';
        renderQueue();
        return;
      }
      var m = /^#item-(\d+)$/.exec(location.hash);
      var want = m ? parseInt(m[1], 10) - 1 : -1;
      if (!(want >= 0 && want < S.queue.length)) {
        want = S.queue[0].done ? nextUnlabelled(0) : 0;
        if (want < 0) { want = 0; }
      }
      await openItem(want);
      document.body.dataset.ready = '1';
    } catch (e) {
      fail(e);
    }
  }
  start();
})();
"""


def app_html() -> str:
    """The judges' page: one HTML document with its CSS and script inline (nothing else to fetch but the API)."""
    return (
        "<!DOCTYPE html>\n"
        '<html lang="en">\n<head>\n<meta charset="utf-8">\n'
        '<meta name="viewport" content="width=device-width, initial-scale=1">\n'
        '<meta name="referrer" content="no-referrer">\n'
        '<link rel="icon" href="data:,">\n'
        "<title>PiL-World annotation</title>\n"
        f"<style>{_CSS}</style>\n</head>\n<body>{_BODY}<script>{_JS}</script>\n</body>\n</html>\n"
    )

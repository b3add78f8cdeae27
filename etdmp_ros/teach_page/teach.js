// The teaching page's script (etdmp_ros/nodes/teach.py serves it; docs/teach.md).
//
// Draw: pointer events (mouse, pen, touch) on the canvas, each point [x, y, t] in the canvas's
// logical pixels and the event's timeStamp in ms (coalesced events included: a pen's full
// rate). Teach: POST /api/teach {name, strokes}; the answer is dmp_server's own report and the
// skill's generalizations, drawn as the paper's Fig. 5. Write: POST /api/write {name,
// duration}. The camera view polls /api/camera.jpg and /api/overlay while the page is visible
// (the node subscribes the camera only while a page asks) and draws the image with the plan and
// the pen's trace over it, zoomed in on them if asked.
'use strict';

const teach = {
  config: null,
  strokes: [],
  current: null,
  taught: null,
  cameraFrames: 0,
  overlay: null,
  lastAnswer: null,
};
window.teach = teach;

const $ = (id) => document.getElementById(id);
const draw = $('draw');
const ctx = draw.getContext('2d');
const COLOURS = {demo: '#b5b5b5', etdmp: '#1a9850', dmp: '#f46d43', stroke: '#1d3f73',
                 plan: '#29d15b', trace: '#ff2bd6'};

function sleep(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

function say(id, text, kind) {
  const element = $(id);
  element.textContent = text;
  element.className = 'message ' + (kind || '');
}

// ---------------------------------------------------------------------------- drawing

function canvasPoint(event) {
  const rect = draw.getBoundingClientRect();   // includes the border: clientLeft/Top
  const x = (event.clientX - rect.left - draw.clientLeft) * draw.width / draw.clientWidth;
  const y = (event.clientY - rect.top - draw.clientTop) * draw.height / draw.clientHeight;
  return [Math.round(x * 100) / 100, Math.round(y * 100) / 100,
          Math.round(event.timeStamp * 1000) / 1000];
}

function pointCount() {
  return teach.strokes.reduce((n, stroke) => n + stroke.length, 0);
}

function grid() {
  ctx.fillStyle = '#fff';
  ctx.fillRect(0, 0, draw.width, draw.height);
  const metres = teach.config ? teach.config.canvas.metres : 0.4;
  const step = 0.05 * draw.width / metres;   // 5 cm squares
  ctx.strokeStyle = '#eceff3';
  ctx.lineWidth = 1;
  ctx.beginPath();
  for (let x = draw.width / 2 % step; x < draw.width; x += step) {
    ctx.moveTo(x, 0);
    ctx.lineTo(x, draw.height);
  }
  for (let y = draw.height / 2 % step; y < draw.height; y += step) {
    ctx.moveTo(0, y);
    ctx.lineTo(draw.width, y);
  }
  ctx.stroke();
  ctx.fillStyle = '#999';
  ctx.font = '12px sans-serif';
  ctx.fillText('robot base', draw.width / 2 - 30, 14);
  ctx.fillText('5 cm squares', 8, draw.height - 8);
}

function redraw() {
  grid();
  ctx.strokeStyle = COLOURS.stroke;
  ctx.lineWidth = 3;
  ctx.lineCap = 'round';
  ctx.lineJoin = 'round';
  for (const stroke of teach.strokes) {
    ctx.beginPath();
    stroke.forEach(([x, y], k) => (k ? ctx.lineTo(x, y) : ctx.moveTo(x, y)));
    if (stroke.length === 1) {
      ctx.lineTo(stroke[0][0] + 0.1, stroke[0][1]);
    }
    ctx.stroke();
  }
  const first = teach.strokes.length && teach.strokes[0][0];
  if (first) {
    ctx.fillStyle = COLOURS.stroke;
    ctx.beginPath();
    ctx.arc(first[0], first[1], 5, 0, 2 * Math.PI);
    ctx.fill();
  }
  const points = pointCount();
  let seconds = 0;
  if (points) {
    const last = teach.strokes[teach.strokes.length - 1];
    seconds = (last[last.length - 1][2] - teach.strokes[0][0][2]) / 1000;
  }
  $('stroke-info').textContent = points ?
    `${teach.strokes.length} stroke(s), ${points} points, ${seconds.toFixed(2)} s` : '';
}

draw.addEventListener('pointerdown', (event) => {
  if (event.pointerType === 'mouse' && event.button !== 0) {
    return;
  }
  event.preventDefault();
  draw.setPointerCapture(event.pointerId);
  teach.current = [canvasPoint(event)];
  teach.strokes.push(teach.current);
  redraw();
});

draw.addEventListener('pointermove', (event) => {
  if (!teach.current) {
    return;
  }
  const events = event.getCoalescedEvents ? event.getCoalescedEvents() : [];
  for (const e of (events.length ? events : [event])) {
    teach.current.push(canvasPoint(e));
  }
  redraw();
});

function endStroke(event) {
  if (teach.current) {
    teach.current.push(canvasPoint(event));
    teach.current = null;
    redraw();
  }
}
draw.addEventListener('pointerup', endStroke);
draw.addEventListener('pointercancel', endStroke);

$('clear').addEventListener('click', () => {
  teach.strokes = [];
  teach.current = null;
  redraw();
  say('teach-message', '');
});

// ---------------------------------------------------------------------------- requests

async function post(path, body) {
  let response;
  try {
    response = await fetch(path, {method: 'POST', headers: {'Content-Type': 'application/json'},
                                  body: JSON.stringify(body)});
  } catch (error) {
    return {ok: false, error: `the teach node does not answer (${error.message})`};
  }
  let answer;
  try {
    answer = await response.json();
  } catch (error) {
    answer = {ok: false, error: `HTTP ${response.status} ${response.statusText}`};
  }
  teach.lastAnswer = answer;
  return answer;
}

$('teach').addEventListener('click', async () => {
  const name = $('name').value.trim();
  const button = $('teach');
  button.disabled = true;
  say('teach-message', `teaching ${name || '(no name)'}...`, 'busy');
  const answer = await post('/api/teach', {name, strokes: teach.strokes});
  button.disabled = false;
  if (!answer.ok) {
    say('teach-message', answer.error, 'error');
    return;
  }
  teach.taught = answer.skill;
  say('teach-message', answer.message, 'ok');
  $('write').disabled = false;
  $('write').textContent = `Write ${answer.skill.name}`;
  showSkill(answer.skill);
});

$('write').addEventListener('click', async () => {
  if (!teach.taught) {
    return;
  }
  const text = $('duration').value.trim();
  const duration = text === '' ? null : Number(text);
  const button = $('write');
  button.disabled = true;
  say('write-message', `planning ${teach.taught.name}...`, 'busy');
  const answer = await post('/api/write', {name: teach.taught.name, duration});
  button.disabled = false;
  say('write-message', answer.ok ? answer.message : answer.error, answer.ok ? 'ok' : 'error');
});

// ---------------------------------------------------------------------------- Fig. 5

function bounds(lists) {
  let box = [Infinity, Infinity, -Infinity, -Infinity];
  for (const list of lists) {
    for (const [x, y] of list) {
      box = [Math.min(box[0], x), Math.min(box[1], y), Math.max(box[2], x),
             Math.max(box[3], y)];
    }
  }
  return box;
}

function polyline(c, points, colour, width, dashed) {
  c.strokeStyle = colour;
  c.lineWidth = width;
  c.setLineDash(dashed ? [6, 4] : []);
  c.beginPath();
  points.forEach(([x, y], k) => (k ? c.lineTo(x, y) : c.moveTo(x, y)));
  c.stroke();
  c.setLineDash([]);
}

function panel(skill, item, method) {
  const figure = document.createElement('figure');
  const canvas = document.createElement('canvas');
  canvas.width = 320;
  canvas.height = 240;
  const caption = document.createElement('figcaption');
  const label = method === 'etdmp' ? 'ET-DMP' : 'DMP';
  const result = item[method];
  caption.textContent = `${label}, start in ${item.quadrant}` + (item.own ? ' = demo\'s' : '') +
    (result.path ? `, nRMSE ${result.nrmse.toFixed(3)}` : ': refused');
  figure.append(canvas, caption);
  const c = canvas.getContext('2d');
  const lists = [skill.demo, [item.start], [skill.goal]];
  if (result.path) {
    lists.push(result.path);
  }
  const [x0, y0, x1, y1] = bounds(lists);
  const scale = 0.86 * Math.min(canvas.width / Math.max(x1 - x0, 1e-9),
                                canvas.height / Math.max(y1 - y0, 1e-9));
  const ox = canvas.width / 2 - scale * (x0 + x1) / 2;
  const oy = canvas.height / 2 - scale * (y0 + y1) / 2;
  const map = (list) => list.map(([x, y]) => [ox + scale * x, oy + scale * y]);
  polyline(c, map(skill.demo), COLOURS.demo, 5, false);
  if (result.path) {
    polyline(c, map(result.path), COLOURS[method], 2.5, method === 'dmp');
  } else {
    c.fillStyle = '#8a1c1c';
    c.font = '12px sans-serif';
    wrap(c, result.error, 8, 18, canvas.width - 16, 15);
  }
  const [[sx, sy]] = map([item.start]);
  const [[gx, gy]] = map([skill.goal]);
  c.fillStyle = COLOURS[method];
  c.beginPath();
  c.arc(sx, sy, 6, 0, 2 * Math.PI);
  c.fill();
  c.strokeStyle = '#000';
  c.lineWidth = 2;
  c.beginPath();
  c.arc(gx, gy, 7, 0, 2 * Math.PI);
  c.stroke();
  return figure;
}

function wrap(c, text, x, y, width, height) {
  let line = '';
  for (const word of text.split(' ')) {
    if (c.measureText(line + word).width > width && line) {
      c.fillText(line, x, y);
      line = '';
      y += height;
    }
    line += word + ' ';
  }
  c.fillText(line, x, y);
}

function showSkill(skill) {
  const panels = $('panels');
  panels.replaceChildren();
  for (const method of ['etdmp', 'dmp']) {
    for (const item of skill.panels) {
      panels.append(panel(skill, item, method));
    }
  }
  $('skill-info').textContent = `${skill.name}: ${skill.samples} samples over ` +
    `${skill.duration.toFixed(2)} s from ${skill.strokes} stroke(s); the demonstration ` +
    `starts in quadrant ${skill.quadrant} of its goal. ET-DMP (top) keeps its shape from ` +
    'every start; the plain DMP (bottom) only from the demonstration\'s own quadrant.';
}

// ---------------------------------------------------------------------------- camera

const view = $('view');
const vctx = view.getContext('2d');
let imageUrl = null;

function showImage(blob) {
  return new Promise((resolve) => {
    const image = $('camera');
    const url = URL.createObjectURL(blob);
    image.onload = () => {
      if (imageUrl) {
        URL.revokeObjectURL(imageUrl);
      }
      imageUrl = url;
      teach.cameraFrames += 1;
      resolve(true);
    };
    image.onerror = () => resolve(false);
    image.src = url;
  });
}

// The part of the image shown: all of it, or (zoom) the plan and the trace with a margin, at
// least half the image wide, in the image's aspect.
function crop(data, width, height) {
  const lists = [data.plan || [], data.trace || []].filter((list) => list.length);
  if (!$('zoom').checked || !lists.length) {
    return [0, 0, width, height];
  }
  const [x0, y0, x1, y1] = bounds(lists);
  let w = Math.max(2 * (x1 - x0), 2 * (y1 - y0) * width / height, width / 2);
  w = Math.min(w, width);
  const h = w * height / width;
  const left = Math.min(Math.max((x0 + x1 - w) / 2, 0), width - w);
  const top = Math.min(Math.max((y0 + y1 - h) / 2, 0), height - h);
  return [left, top, w, h];
}

function drawView(data) {
  teach.overlay = data;
  $('status').textContent = data.status ? `controller: ${data.status}` : '';
  const image = $('camera');
  if (!image.naturalWidth) {
    return;
  }
  const [width, height] = data.size || [image.naturalWidth, image.naturalHeight];
  const [left, top, w, h] = crop(data, width, height);
  vctx.drawImage(image, left * image.naturalWidth / width, top * image.naturalHeight / height,
                 w * image.naturalWidth / width, h * image.naturalHeight / height,
                 0, 0, view.width, view.height);
  const map = (list) => list.map(([x, y]) => [(x - left) * view.width / w,
                                              (y - top) * view.height / h]);
  vctx.globalAlpha = 0.7;   // the plan wide underneath, the pen's trace on top of it
  polyline(vctx, map(data.plan || []), COLOURS.plan, 6, false);
  vctx.globalAlpha = 1;
  polyline(vctx, map(data.trace || []), COLOURS.trace, 2, false);
}

async function cameraLoop() {
  for (;;) {
    if (document.visibilityState !== 'visible') {
      await sleep(500);
      continue;
    }
    const started = performance.now();
    try {
      const response = await fetch('/api/camera.jpg', {cache: 'no-store'});
      if (response.ok) {
        if (await showImage(await response.blob())) {
          $('camera-note').textContent = 'Camera: live.';
        }
      } else {
        $('camera-note').textContent = `Camera: ${await response.text()}`;
      }
      drawView(await (await fetch('/api/overlay', {cache: 'no-store'})).json());
    } catch (error) {
      $('camera-note').textContent = `Camera: the teach node does not answer (${error.message})`;
    }
    const period = 1000 * (teach.config ? teach.config.camera_period : 0.2);
    await sleep(Math.max(20, period - (performance.now() - started)));
  }
}

async function start() {
  try {
    teach.config = await (await fetch('/api/config')).json();
    const {width, height, metres} = teach.config.canvas;
    draw.width = width;
    draw.height = height;
    $('canvas-note').textContent = `The table as the camera sees it, robot base at the top: ` +
      `${(100 * metres).toFixed(0)} x ${(100 * metres * height / width).toFixed(0)} cm. ` +
      'Slow down at corners, as you would with a pen: a sharp corner drawn at full speed ' +
      'comes out rounded.';
  } catch (error) {
    say('teach-message', `the teach node does not answer (${error.message})`, 'error');
  }
  redraw();
  cameraLoop();
}

start();

// The sync channel to a Tessera node: one WebSocket speaking the binary protocol. After the
// handshake, a run loop (rate Hz) collects scene changes, sends them progressively (buffers
// deflated when CompressionStream exists, rate-controlled on ws.bufferedAmount) and asks for
// a frame after every iteration that changed something. The render settings (AO samples, ray
// depth) go as a settings record after the handshake and again whenever they change, the
// refinement target (samples per pixel of a still) likewise as a refine record, and the frame
// budget (milliseconds an interactive frame should take) as a budget record, and the H.264
// display's bitrate as a video record (only in an h264 session). A frame answers the render
// request of its frame number and every earlier one, refined or not: the node merges requests
// and replaces a rendered frame that waits for a slow link by a newer one (its refinement, or
// a later request's), so counting frames would lose requests for good. Buffers and
// textures the node can load from their URLs go as references (docs/protocol.md, "References";
// off with the option `references: false`): in messages of their own, before the rest of the
// scene change, which follows at once (the node applies it after its answers; a mesh whose
// buffers are missing waits there for them); a refused one is uploaded when its answer comes,
// unless a newer record for the same id went out meanwhile. While answers are outstanding, the
// channel sends at most half of what the node holds back for it (max_message_bytes). On
// connection loss it reconnects with back-off and re-sends the whole scene and the settings.
import { encodeClient, decodeServer, clientRecordSize, ProtocolError } from './Protocol.js';
import { SceneSync } from './SceneSync.js';
import { hasCompressionStream, deflate } from './Features.js';
import { loadTexture } from './TextureEncoder.js';
import { sameSettings } from './RenderSettings.js';
import { redact } from './AccessToken.js';
import { pendingValues } from '../reader/GltfLoader.js';

const DEFLATE_MIN_BYTES = 256;
const TEXTURE_BYTES = 1 << 18;  // what a texture counts for in the upload progress (its size is not known yet)
const MAX_OUTSTANDING_RENDERS = 2;
// The node closes a WebSocket with 4401 when it refuses the page's access token (missing,
// expired, invalid: the reason says which; docs/protocol.md). The same page cannot do better
// by trying again, so the channel stops there.
const CLOSE_BAD_TOKEN = 4401;
const REF_KIND = { buffer_ref: 'buffer', texture_ref: 'texture' };  // a reference record's `what` in the node's answer
const isRef = (r) => r.type in REF_KIND;
// The buffer or texture id a record sets, removes or references ('buffer:3'), or null.
function recordKey(r) {
  if (r.type === 'buffer' || r.type === 'buffer_ref') return `buffer:${r.id}`;
  if (r.type === 'texture' || r.type === 'texture_ref') return `texture:${r.id}`;
  if (r.type === 'remove' && (r.what === 'buffer' || r.what === 'texture')) return `${r.what}:${r.id}`;
  return null;
}
const uploadBytes = (r) => (r.type === 'buffer' ? r.data.byteLength : TEXTURE_BYTES);
// Refused references are uploaded, so the scene is complete all the same: one console warning
// per page load says so, not one per reference.
let refusalsWarned = false;

export class SyncChannel {
  constructor({ url, handshake, settings = null, videoKbps = 0, rate = 30, highWater = 4 << 20, messageBytes = 1 << 20, references = true,
    onFrame = () => {}, onState = () => {}, onServerError = () => {}, onStats = () => {}, onProgress = () => {},
    onReferencesAnswered = () => {}, onRequest = () => {}, onIdle = () => {} }) {
    Object.assign(this, { url, handshake, settings, videoKbps, rate, highWater, messageBytes, onFrame, onState, onServerError, onStats, onProgress,
      onReferencesAnswered, onRequest, onIdle });
    this.sync = new SceneSync({ references });
    this.queue = [];          // {size, record: Promise|object}
    this.frameNumber = 0;     // of the last render request sent
    this.answered = 0;        // the highest frame number a frame has come back with
    this.renderWanted = false;
    this.state = 'idle';
    this.retry = 0;
    this.progress = { queued: 0, sent: 0 };
    this.closed = false;
    this.session = 0;         // handshake replies so far
    // 'buffer:3' -> [{ref, seq, group}, ...]: references sent and not answered yet, oldest first
    // (a page may reference one id again before the first answer; the node answers in order).
    this.unanswered = new Map();
    this.groups = [];         // the messages of references not answered in full: {left, sentAt}, oldest first
    this.sentBytes = 0;       // bytes sent in this session
    this.latest = new Map();  // 'buffer:3' -> seq of the last record sent for that buffer or texture id
    this.seq = 0;
    this.answerWaiters = [];  // flushes waiting for room: resolved by any answer or the session's end
    this.lastChange = -Infinity;  // performance.now() of the last iteration that found a change
    this.soon = false;        // an iteration is scheduled for a change (tickSoon)
  }

  connect() {
    if (this.closed) return;
    this.setState('connecting');
    let ws;
    try { ws = new WebSocket(this.url); } catch (e) { this.lost(`cannot open ${redact(this.url)}: ${e.message}`); return; }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    let opened = false;
    ws.onopen = () => {
      opened = true;
      this.send(encodeClient([{ type: 'handshake', ...this.handshake }]));  // alone in its message
      this.setState('handshake');
    };
    ws.onmessage = (e) => this.receive(e.data);
    ws.onclose = (e) => { if (this.ws === ws) this.closedBy(e, opened); };
    ws.onerror = () => {};
  }

  // A browser tells a page nothing of an upgrade the node refused with an HTTP status (a foreign
  // origin, too many connections, a full node): only that it never opened.
  closedBy(e, opened) {
    if (e.code === CLOSE_BAD_TOKEN) this.fatal = e.reason || 'access token refused';
    this.lost(e.reason || (opened ? `connection closed (code ${e.code})`
      : `the node refused the connection or cannot be reached (code ${e.code}; the browser's console shows the HTTP status)`));
  }

  setState(state, detail = '') {
    this.state = state;
    this.onState(state, detail);
  }

  lost(reason) {
    this.ws = null;
    this.dropUnanswered();
    clearInterval(this.timer);
    this.timer = null;
    if (this.closed) return;
    if (this.fatal) { this.setState('failed', this.fatal); return; }
    const delay = Math.min(10000, 500 * 2 ** this.retry++);
    this.setState('disconnected', `${reason}; reconnecting in ${(delay / 1000).toFixed(1)} s`);
    this.reconnectTimer = setTimeout(() => this.connect(), delay);
  }

  // A new session at once (display="auto" switching to H.264 with a new handshake): the old
  // connection is dropped unheard, and the scene goes to the new session as after a reconnect.
  restart() {
    if (this.closed) return;
    const ws = this.ws;
    this.ws = null;
    this.dropUnanswered();
    clearInterval(this.timer);
    this.timer = null;
    clearTimeout(this.reconnectTimer);
    if (ws) { ws.onmessage = null; ws.onclose = null; ws.close(); }
    this.connect();
  }

  close() {
    this.closed = true;
    clearInterval(this.timer);
    clearTimeout(this.reconnectTimer);
    this.dropUnanswered();
    if (this.ws) { const ws = this.ws; this.ws = null; ws.close(); }
  }

  // The latest scene and view; picked up by the next run-loop iteration.
  setScene(scene, view) {
    this.scene = scene;
    this.view = view;
    this.dirty = true;
    this.tickSoon();
  }

  // A change a period or more after the last one goes out at once instead of at the run
  // loop's next iteration (up to a period later: 33 ms at 30 Hz, the first step of a drag
  // waited that long). Within a period of the last change it waits for the next iteration, so
  // the rate still bounds how often the client sends.
  tickSoon() {
    if (this.state !== 'ready' || this.soon || performance.now() - this.lastChange < 1000 / this.rate) return;
    this.soon = true;
    queueMicrotask(() => {
      this.soon = false;
      this.tick();
    });
  }

  // New render settings {aoSamples, maxDepth, refineSamples, frameBudget}; the next run-loop
  // iteration sends a settings record when the first two differ from the last ones, a refine
  // record when the refinement target does, a budget record when the frame budget does, and a
  // render request.
  setSettings(settings) {
    if (sameSettings(settings, this.settings)) return;
    const old = this.settings;
    this.settings = settings;
    if (!old || old.aoSamples !== settings.aoSamples || old.maxDepth !== settings.maxDepth) this.settingsDirty = true;
    if (settings.refineSamples !== undefined && (!old || old.refineSamples !== settings.refineSamples)) this.refineDirty = true;
    if (settings.frameBudget !== undefined && (!old || old.frameBudget !== settings.frameBudget)) this.budgetDirty = true;
  }

  // The H.264 bitrate in kbit/s (0: the node's own): the next run-loop iteration of an h264
  // session sends a video record when it differs from the last one. 0 sends nothing (the video
  // record's 0 means "unchanged"), so the last bitrate holds until the next session.
  setVideoKbps(kbps) {
    if (kbps === this.videoKbps) return;
    this.videoKbps = kbps;
    this.videoDirty = true;
  }

  // Asks for a keyframe (the H.264 decoder lost the stream): a video record with the keyframe
  // flag, and a render request in the same message, since the keyframe comes with the next
  // frame. Outside a session nothing is sent: the next one starts with a keyframe anyway.
  requestKeyframe() {
    if (this.state !== 'ready') return;
    this.requestRender([{ type: 'video', bitrateKbps: 0, keyframe: true }]);
  }

  receive(data) {
    let records;
    try { records = decodeServer(new Uint8Array(data)); } catch (e) {
      this.onServerError({ codeName: 'client', message: `bad message from the server: ${e instanceof ProtocolError ? e.message : e}` });
      return;
    }
    const answers = [];  // the node answers a message's references in one message
    for (const r of records) {
      if (r.type === 'handshake_reply') {
        this.reply = r;
        this.retry = 0;
        if (r.maxMessageBytes) this.messageBytes = Math.min(this.messageBytes, r.maxMessageBytes);
        this.session++;
        this.dropUnanswered();
        this.sentBytes = 0;
        this.latest.clear();
        this.sync.reset();
        this.queue = [];
        this.answered = this.frameNumber;  // the old session's requests are gone with it
        this.dirty = true;
        this.setState('ready', `${r.serverVersion || 'Tessera'}, ${r.nodes} node${r.nodes > 1 ? 's' : ''}, ${r.renderer}, ${r.display}`);
        this.settingsDirty = !!this.settings;
        this.refineDirty = !!this.settings && this.settings.refineSamples !== undefined;
        this.budgetDirty = !!this.settings && this.settings.frameBudget !== undefined;
        this.videoDirty = this.videoKbps > 0;
        clearInterval(this.timer);
        // An iteration a period; one within half a period of a change sent early (tickSoon)
        // waits for the next, so changes go out at most twice a period.
        this.timer = setInterval(() => { if (performance.now() - this.lastChange >= 500 / this.rate) this.tick(); }, 1000 / this.rate);
        this.tick();
      } else if (r.type === 'frame') {
        // A frame answers its request and every earlier one, whether it is the requested frame
        // or a refinement of it (same frame number; the requested one may have been replaced
        // on its way by it) or a later request's (earlier ones merged or replaced).
        if (r.frame > this.answered && r.frame <= this.frameNumber) this.answered = r.frame;
        this.onFrame(r);
        if (this.renderWanted && this.outstanding < MAX_OUTSTANDING_RENDERS) this.requestRender();
      } else if (r.type === 'error') {
        if (r.fatal) this.fatal = `${r.codeName}: ${r.message}`;
        // The node may have refused a message of references as a whole (it then answers none of
        // them): what is unanswered is uploaded (an answer that still comes changes nothing).
        this.refuseUnanswered();
        this.onServerError(r);
      } else if (r.type === 'stats') {
        this.onStats(r);
      } else if (r.type === 'reference') {
        answers.push(r);
      }
    }
    if (answers.length) this.answer(answers);
  }

  send(bytes) {
    if (this.ws && this.ws.readyState === 1) {
      this.ws.send(bytes);
      this.sentBytes += bytes.byteLength;
    }
  }

  // Sends records and notes, for each buffer and texture among them, that this is now the
  // latest record for its id (a refused reference's upload must not replace a newer one).
  sendRecords(records) {
    const bytes = encodeClient(records);
    for (const r of records) {
      const k = recordKey(r);
      if (k) this.latest.set(k, ++this.seq);
    }
    this.send(bytes);
  }

  // Prepares a record for the wire: buffers deflated, textures loaded and encoded.
  prepare(r) {
    // A buffer of a deferred glTF load (one whose reference the node refused, say) goes once its
    // values are in; the records queued after it wait, since they may use it.
    const pending = r.type === 'buffer' && pendingValues(r.data);
    if (pending) {
      return { size: r.data.byteLength, record: pending.then(() => this.prepare(r).record, (e) => {
        this.onServerError({ codeName: 'buffer', message: `buffer ${r.id}: ${e.message || e}` });
        return null;
      }) };
    }
    if (r.type === 'buffer' && r.data.byteLength >= DEFLATE_MIN_BYTES && hasCompressionStream()) {
      const raw = new Uint8Array(r.data.buffer, r.data.byteOffset, r.data.byteLength);
      return { size: r.data.byteLength, record: deflate(raw).then((z) => (z.length < raw.length ? { ...r, deflated: z } : r), () => r) };
    }
    if (r.type === 'texture') {
      return { size: TEXTURE_BYTES, record: loadTexture(r.desc).then((t) => ({ type: 'texture', id: r.id, ...t }), (e) => {
        this.onServerError({ codeName: 'texture', message: `texture ${r.desc.url}: ${e.message || e}` });
        return null;
      }) };
    }
    return { size: clientRecordSize(r), record: r };
  }

  tick() {
    if (this.state !== 'ready') return;
    if (this.settingsDirty && this.settings) {
      this.settingsDirty = false;
      const r = { type: 'settings', aoSamples: this.settings.aoSamples, maxDepth: this.settings.maxDepth };
      this.queue.push({ size: clientRecordSize(r), record: r });
      this.changed = true;
    }
    if (this.refineDirty && this.settings) {
      this.refineDirty = false;
      const r = { type: 'refine', samples: this.settings.refineSamples };
      this.queue.push({ size: clientRecordSize(r), record: r });
      this.changed = true;
    }
    if (this.budgetDirty && this.settings) {
      this.budgetDirty = false;
      const r = { type: 'budget', frameMs: this.settings.frameBudget };
      this.queue.push({ size: clientRecordSize(r), record: r });
      this.changed = true;
    }
    if (this.videoDirty && this.reply && this.reply.display === 'h264') {
      this.videoDirty = false;
      if (this.videoKbps > 0) {
        const r = { type: 'video', bitrateKbps: this.videoKbps, keyframe: false };
        this.queue.push({ size: clientRecordSize(r), record: r });
      }
    }
    if (this.dirty && this.scene) {
      this.dirty = false;
      const records = this.sync.diff(this.scene, this.view);
      // The references first, as one item: what follows waits for the node's answers.
      const refs = records.filter(isRef);
      const items = refs.length ? [{ refs, size: refs.reduce((n, r) => n + uploadBytes(r.upload), 0) }] : [];
      for (const r of records) if (!isRef(r)) items.push(this.prepare(r));
      for (const p of items) {
        this.queue.push(p);
        this.progress.queued += p.size;
      }
      if (records.length) {
        this.changed = true;
        this.lastChange = performance.now();
      }
    }
    this.flush();
  }

  async flush() {
    if (this.flushing) return;
    this.flushing = true;
    let sent = false;
    try {
      const session = this.session;
      while (this.queue.length && this.ws && this.ws.bufferedAmount < this.highWater) {
        if (this.queue[0].refs) {
          if (!(await this.sendRefs(this.queue.shift(), session))) break;
          sent = true;
          continue;
        }
        // Pack records into one message up to messageBytes (a larger record goes alone).
        const batch = [];
        let bytes = 8;
        while (this.queue.length && !this.queue[0].refs) {
          const item = this.queue[0];
          const rec = await item.record;
          const size = rec ? clientRecordSize(rec) : 0;
          if (batch.length && bytes + size > this.messageBytes) break;
          if (this.queue[0] !== item) break;  // a refused reference's upload went ahead meanwhile
          this.queue.shift();
          this.progress.sent += item.size;
          if (rec) { batch.push(rec); bytes += size; }
        }
        if (batch.length) {
          if (!(await this.roomFor(bytes, session))) break;
          this.sendRecords(batch);
          sent = true;
        }
        this.onProgress(this.progress.sent, this.progress.queued);
      }
      if (!this.queue.length) this.progress = { queued: 0, sent: 0 };
      // A render request after every iteration that sent something: also after the later
      // parts of an upload that the send-buffer limit spread over several iterations, so the
      // node renders the scene once it is complete.
      if (this.changed || sent) {
        this.changed = false;
        this.requestRender();
      }
      if (this.idle) this.onIdle();
    } finally {
      this.flushing = false;
    }
  }

  // Nothing left to send and every render request answered: the last frame that came is of
  // everything sent. (Checked after each run-loop iteration.)
  get idle() {
    return this.state === 'ready' && !this.queue.length && !this.dirty && !this.changed && !this.renderWanted
      && this.outstanding === 0 && !this.groups.length;
  }

  // What the node holds back for this session while it loads references: half its limit, so
  // a camera move or a render request always fits beside.
  get holdBytes() { return ((this.reply && this.reply.maxMessageBytes) || this.messageBytes) / 2; }

  // Waits until `bytes` more can be sent without the node holding more than holdBytes of
  // messages behind references it has not answered (it refuses messages beyond its limit).
  // False when the session ended meanwhile: the next one sends everything again.
  async roomFor(bytes, session) {
    while (this.groups.length && this.sentBytes - this.groups[0].sentAt + bytes > this.holdBytes) {
      await new Promise((r) => this.answerWaiters.push(r));
      if (session !== this.session || !this.ws) return false;
    }
    return session === this.session && !!this.ws;
  }

  // Sends references in messages of their own (each answered by the node in one message of
  // `reference` records) without waiting for the answers: what follows goes out at once.
  async sendRefs(item, session) {
    let batch = [], bytes = 8;
    const flush = async () => {
      if (!(await this.roomFor(bytes, session))) return false;
      const group = { left: batch.length, sentAt: 0 };
      const seq0 = this.seq;
      this.sendRecords(batch);
      group.sentAt = this.sentBytes;
      batch.forEach((r, i) => {
        const k = recordKey(r);
        if (!this.unanswered.has(k)) this.unanswered.set(k, []);
        this.unanswered.get(k).push({ ref: r, seq: seq0 + i + 1, group });
      });
      this.groups.push(group);
      batch = [];
      bytes = 8;
      return true;
    };
    for (const r of item.refs) {
      const size = clientRecordSize(r);
      if (batch.length && bytes + size > this.messageBytes && !(await flush())) return false;
      batch.push(r);
      bytes += size;
    }
    if (batch.length && !(await flush())) return false;
    this.onProgress(this.progress.sent, this.progress.queued);
    return true;
  }

  // Reference answers: ok, the id is set on the node; refused, its upload goes ahead of what
  // is queued, unless a newer record for that id was sent since.
  answer(answers) {
    const refused = [], groups = [];
    for (const r of answers) {
      const k = `${r.what}:${r.id}`, waiting = this.unanswered.get(k);
      if (!waiting) continue;  // not a reference waiting for its answer (or refused already after an error)
      const u = waiting.shift();
      if (!waiting.length) this.unanswered.delete(k);
      if (r.ok) this.progress.sent += uploadBytes(u.ref.upload);
      else refused.push({ ...u, message: r.message });
      groups.push(u.group);
    }
    if (refused.length) this.uploadRefused(refused);
    for (const g of groups) this.answered1(g);
  }

  // One reference of a group answered (or given up on): a group answered in full makes room.
  answered1(group) {
    if (--group.left > 0) return;
    this.groups = this.groups.filter((g) => g !== group);
    if (!this.groups.length) this.onReferencesAnswered();
    const waiters = this.answerWaiters;
    this.answerWaiters = [];
    waiters.forEach((w) => w());
  }

  // Queues the uploads of refused references (those still the latest record for their id) ahead
  // of the rest, and warns once per page load.
  uploadRefused(refused) {
    const due = refused.filter((u) => this.latest.get(recordKey(u.ref)) === u.seq);
    // An upload counts in the progress for the reference it replaces (already queued).
    this.queue.unshift(...due.map((u) => ({ ...this.prepare(u.ref.upload), size: uploadBytes(u.ref.upload) })));
    if (refused.length && !refusalsWarned) {
      refusalsWarned = true;
      console.warn(`Tessera: the node refused ${refused.length} reference${refused.length > 1 ? 's' : ''}, so ` +
        `${refused.length > 1 ? 'they are' : 'it is'} uploaded instead; the first: ${refused[0].message || 'unanswered after a server error'}`);
    }
    if (due.length) this.flush();
  }

  // After an error record: every unanswered reference counts as refused.
  refuseUnanswered() {
    const all = [...this.unanswered.values()].flat();
    this.unanswered.clear();
    if (all.length) this.uploadRefused(all);
    for (const u of all) this.answered1(u.group);
  }

  // The session ended: nothing more will be answered, and the next session sends everything.
  dropUnanswered() {
    this.unanswered.clear();
    this.groups = [];
    const waiters = this.answerWaiters;
    this.answerWaiters = [];
    waiters.forEach((w) => w());
  }

  // Render requests sent that no frame has answered yet.
  get outstanding() { return this.frameNumber - this.answered; }

  // `records`: records to send first, in the same message (a keyframe request); they go at
  // once even when the render request itself has to wait for a frame.
  requestRender(records = []) {
    if (this.outstanding >= MAX_OUTSTANDING_RENDERS) {
      this.renderWanted = true;
      if (records.length) this.send(encodeClient(records));
      return;
    }
    this.renderWanted = false;
    this.send(encodeClient([...records, { type: 'render', frame: ++this.frameNumber }]));
    this.onRequest(this.frameNumber);
  }
}

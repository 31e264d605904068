// Playout: when to show each frame and when to play each audio block so that lips and speech agree.
//
// One clock rules both: performance.now() (ms; here in seconds). A frame of media time m is shown at
//     due(m) = m + offset        (seconds on that clock)
// and the audio sample of media time m is *heard* at the same due(m). offset is fixed by the first
// frame of a connection: its arrival time minus its media time plus a small jitter buffer. Audio
// blocks arrive earlier than the frames of the same media time (the model needs ~100 ms of
// lookahead), so they simply wait in WebAudio's schedule. A frame that arrives after its due time
// pushes offset later by its lateness (a "resync": motion and sound stay together, a short silence
// absorbs the step). When every frame of the last 3 s arrived well ahead of time (the hiccup that
// caused a resync is over), offset moves back by half the excess (a "catch-up": the audio player
// skips the few milliseconds that now overlap), so the delay does not only ever grow; but never
// earlier than the first frame put it: a catch-up gives back what resyncs added, no more. Frames that
// come early by design (a text session's 0.5 s lead, `send --fast`, a late viewer's replay of the sentence
// from its start) used to trigger catch-ups too, and each one cut what the step skipped from both the
// frames and the speech (a text session: 8 frames and 8 audio blocks, 0.27 s, at 6 s in).
//
// WebAudio runs on its own clock; AudioContext.getOutputTimestamp() pairs a context time with the
// performance time at which it leaves the speakers, which converts due(m) into a start time that
// includes the output latency.

export function nowS() {
  return performance.now() / 1000;
}

export class PlayoutClock {
  /** bufferS: jitter buffer added to the first frame's arrival (s). */
  constructor({ bufferS = 0.08 } = {}) {
    this.bufferS = bufferS;
    this.offset = null; // s: due = media + offset
    this.baseOffset = null; // s: the offset the first frame set (catch-ups stop there)
    this.resyncs = 0;
    this.catchups = 0;
    this.minSlack = Infinity; // smallest (due - arrival) since windowStart (s)
    this.windowStart = null;
  }

  reset() {
    this.offset = null;
    this.baseOffset = null;
    this.minSlack = Infinity;
    this.windowStart = null;
  }

  /** Called for every frame on arrival; returns its due time (s, performance clock). */
  arrive(mediaTime, arrival) {
    if (this.offset === null) {
      this.offset = arrival - mediaTime + this.bufferS;
      this.baseOffset = this.offset;
      this.windowStart = arrival;
    }
    const due = mediaTime + this.offset;
    if (arrival > due + 0.001) {
      // Late: move the whole timeline so this frame (and the audio after it) fit again.
      this.offset += arrival - due + this.bufferS / 2;
      this.resyncs += 1;
      this.minSlack = Infinity;
      this.windowStart = arrival;
      return mediaTime + this.offset;
    }
    this.minSlack = Math.min(this.minSlack, due - arrival);
    if (arrival - this.windowStart >= 3.0) {
      const back = Math.min((this.minSlack - this.bufferS) / 2, this.offset - this.baseOffset);
      if (this.minSlack > 1.5 * this.bufferS && back > 0.001) {
        this.offset -= back;
        this.catchups += 1;
      }
      this.minSlack = Infinity;
      this.windowStart = arrival;
    }
    return due;
  }

  due(mediaTime) {
    return this.offset === null ? null : mediaTime + this.offset;
  }
}

/**
 * The frames at the head of `queue` ({due, ...} in frame order; due: s, performance clock) whose due time
 * is at or before `now` (s), taken off the queue: `show` the newest of them (null: none due), `skipped` the
 * older ones. A display refresh shows one frame, so of two frames due in one refresh the older is dropped
 * for the newer (the sound goes on; showing it late would put the face behind the speech). On a steady
 * timeline that one's time passed by at least one frame period (the newer one is a frame later), so a
 * frame is dropped only when the display refreshes less often than frames come (`DisplayRate`) or one
 * refresh came more than a frame late; a catch-up (`PlayoutClock`) also drops the frames it steps over, as
 * the audio player skips their sound. Frames are never shown out of order.
 */
export function takeDue(queue, now) {
  const skipped = [];
  let show = null;
  while (queue.length && queue[0].due <= now) {
    if (show) skipped.push(show);
    show = queue.shift();
  }
  return { show, skipped };
}

/**
 * Display refreshes per second: the requestAnimationFrame callbacks of the last second. The browser runs
 * them at the screen's rate (60/s on most screens) unless drawing the previous picture took longer: a
 * browser drawing WebGL in software (no GPU: headless Chromium with SwiftShader) refreshes a 600 x 600
 * canvas of the head ~15-20 times a second, so about every second frame of a 30 frames/s session is
 * skipped (`takeDue`).
 */
export class DisplayRate {
  constructor({ windowS = 1.0 } = {}) {
    this.windowS = windowS;
    this.times = []; // s: the refreshes of the last windowS
  }

  /** A refresh at time t (s). */
  tick(t) {
    this.times.push(t);
    while (this.times.length && this.times[0] < t - this.windowS) this.times.shift();
  }

  /** Refreshes per second over the window (null before two refreshes). */
  get hz() {
    const n = this.times.length;
    if (n < 2) return null;
    const span = this.times[n - 1] - this.times[0];
    return span > 0 ? (n - 1) / span : null;
  }
}

/** Plays relayed audio blocks (Float32Array samples at rateHz) at their due times. */
export class AudioOut {
  constructor() {
    const Ctx = window.AudioContext || window.webkitAudioContext;
    this.ctx = Ctx ? new Ctx({ latencyHint: "interactive" }) : null;
    this.nextStart = 0; // context time where the previous block ends (for gapless joins)
    this.played = 0;
    this.lateDropped = 0;
    this.muted = 0;
    this.syncErrors = []; // s: when each recent block will be heard minus its due time (last 50)
  }

  /** Median |heard - due| of the recent blocks (ms): how far sound is from the frames' timeline. */
  get syncMs() {
    if (!this.syncErrors.length) return null;
    const s = this.syncErrors.map(Math.abs).sort((a, b) => a - b);
    return 1000 * s[s.length >> 1];
  }

  get running() {
    return this.ctx !== null && this.ctx.state === "running";
  }

  async resume() {
    if (this.ctx && this.ctx.state !== "running") await this.ctx.resume();
  }

  reset() {
    this.nextStart = 0;
  }

  /** Schedule samples (Float32Array, [-1, 1]) of rateHz to be heard at dueS (performance clock, s). */
  schedule(samples, rateHz, dueS) {
    if (!this.running) {
      this.muted += 1;
      return;
    }
    const ctx = this.ctx;
    const ts = ctx.getOutputTimestamp ? ctx.getOutputTimestamp() : null;
    // Context time that is heard at performance time dueS.
    let when = ts && ts.performanceTime > 0
      ? ts.contextTime + (dueS - ts.performanceTime / 1000)
      : ctx.currentTime + (dueS - nowS()) - (ctx.outputLatency || 0);
    let skip = 0;
    // Joins within 15 ms (the output timestamp moves in steps of one audio callback) are made exact:
    // no clicks, and 15 ms of audio-visual offset is far below what anyone notices (~45 ms).
    if (Math.abs(when - this.nextStart) < 0.015) when = this.nextStart;
    else if (when < this.nextStart) {
      // The timeline moved earlier (catch-up): skip what would overlap the audio already scheduled.
      skip = this.nextStart - when;
      when = this.nextStart;
    }
    const earliest = ctx.currentTime + 0.005;
    if (when < earliest) {
      skip += earliest - when;
      when = earliest;
    }
    if (skip >= samples.length / rateHz) {
      this.lateDropped += 1;
      return;
    }
    const buffer = ctx.createBuffer(1, samples.length, rateHz);
    buffer.copyToChannel(samples, 0);
    const src = ctx.createBufferSource();
    src.buffer = buffer;
    src.connect(ctx.destination);
    src.start(when, skip);
    this.nextStart = when + samples.length / rateHz - skip;
    this.played += 1;
    // Performance time at which the block's first (unskipped) sample is heard, vs. its due time.
    const heard = ts && ts.performanceTime > 0
      ? ts.performanceTime / 1000 + (when - ts.contextTime)
      : nowS() + (when - ctx.currentTime) + (ctx.outputLatency || 0);
    this.syncErrors.push(heard - (dueS + skip));
    if (this.syncErrors.length > 50) this.syncErrors.shift();
  }
}

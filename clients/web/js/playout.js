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
// skips the few milliseconds that now overlap), so the delay does not only ever grow.
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
    this.resyncs = 0;
    this.catchups = 0;
    this.minSlack = Infinity; // smallest (due - arrival) since windowStart (s)
    this.windowStart = null;
  }

  reset() {
    this.offset = null;
    this.minSlack = Infinity;
    this.windowStart = null;
  }

  /** Called for every frame on arrival; returns its due time (s, performance clock). */
  arrive(mediaTime, arrival) {
    if (this.offset === null) {
      this.offset = arrival - mediaTime + this.bufferS;
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
      if (this.minSlack > 1.5 * this.bufferS) {
        this.offset -= (this.minSlack - this.bufferS) / 2;
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

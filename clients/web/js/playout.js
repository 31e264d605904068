// Playout: when to show each frame and when to play each audio block so that lips and speech agree.
//
// One clock rules both: performance.now() (ms; here in seconds). A frame of media time m is shown at
//     due(m) = m + offset        (seconds on that clock)
// and the audio sample of media time m is *heard* at the same due(m). offset is fixed by the first
// frame of a connection: its arrival time minus its media time plus a small jitter buffer. Audio
// blocks arrive earlier than the frames of the same media time (the model needs ~100 ms of
// lookahead), so they simply wait in WebAudio's schedule. A frame that arrives after its due time
// pushes offset later by its lateness (a "resync": motion and sound stay together, a short silence
// absorbs the step).
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
  }

  reset() {
    this.offset = null;
  }

  /** Called for every frame on arrival; returns its due time (s, performance clock). */
  arrive(mediaTime, arrival) {
    if (this.offset === null) this.offset = arrival - mediaTime + this.bufferS;
    const due = mediaTime + this.offset;
    if (arrival > due + 0.001) {
      // Late: move the whole timeline so this frame (and the audio after it) fit again.
      this.offset += arrival - due + this.bufferS / 2;
      this.resyncs += 1;
      return mediaTime + this.offset;
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
    if (Math.abs(when - this.nextStart) < 0.004) when = this.nextStart; // join blocks without clicks
    let skip = 0;
    const earliest = ctx.currentTime + 0.005;
    if (when < earliest) {
      skip = earliest - when;
      when = earliest;
      if (skip >= samples.length / rateHz) {
        this.lateDropped += 1;
        return;
      }
    }
    const buffer = ctx.createBuffer(1, samples.length, rateHz);
    buffer.copyToChannel(samples, 0);
    const src = ctx.createBufferSource();
    src.buffer = buffer;
    src.connect(ctx.destination);
    src.start(when, skip);
    this.nextStart = when + samples.length / rateHz - skip;
    this.played += 1;
  }
}

"""``facecast view`` with a window: the stream drawn live, its audio played in sync.

Threads: the window (glfw, on the calling thread: GUI toolkits want the main thread) draws; a
receiver thread runs its own asyncio loop, connects as a deltas viewer (again and again: when the
session ends or the server restarts it waits for the session to come back, like the browser
viewer) and hands every frame over with its arrival time, and every audio block straight to the
sound output (never through the window's loop: a slow draw under load must not starve the sound
device); PortAudio's callback thread plays.

Sync is the browser viewer's scheme (clients/web/js/playout.js): one clock (``time.perf_counter``);
frame of media time m is shown at ``m + offset``, fixed by the first frame's arrival plus a jitter
buffer and moved later by a late frame; the audio callback asks which media time its buffer will be
heard at (PortAudio's DAC time mapped to the same clock) and copies those samples, so the speech is
delayed exactly like the frames. Drawing uses the offline renderer (offscreen) and copies each
image into the window's framebuffer (a second, windowed moderngl context). Both contexts are GLX
(the renderer's backend is forced to moderngl's default): Mesa refuses a GLX MakeCurrent in a
process that has created EGL contexts (X error BadAccess), so one process uses one API.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import queue
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from assets.heads.mesh import HeadMesh
from clients.errors import ClientError
from clients.render.renderer import HeadRenderer, RenderConfig
from clients.viewer.stream import ViewerStreamConfig, backoff, connect_viewer
from clients.viewer.video import framing
from wire import protocol as P

REST_EASE_S = 0.2
"""How long the face takes to ease to rest after a session's last frame (the browser viewer's too)."""
REWATCH_MAX_S = 1.0
"""s: the longest wait between the window's attempts to watch its session again once it has ended (or once the
first wait, ``wait_s``, has run out): from :data:`clients.viewer.stream.RETRY_S` the wait doubles up to this. Each
attempt asks the server to hold the window for ``wait_s`` (the view query's ``wait``), so against this project's
server a session that comes back is watched from its first frame and audio block, with one connection per
``wait_s`` meanwhile; the back-off is for a server that holds nobody (or ``--wait 0``): retried every RETRY_S for as
long as the session stayed away, the window opened 17 connections a second (each one a WebSocket handshake the server
closes with 4004), backed off one a second, and a session that comes back is still picked up within this (the
browser viewer retries a server it lost every second too)."""


@dataclass
class LiveStats:
    """What the window did: frames shown/received, index gaps (lost), frames skipped because a
    newer one was due, timeline moves (resyncs), connections, audio blocks received and whether a
    sound device played them, delivery delay median (ms, server send -> receipt)."""

    shown: int = 0
    first_index: int | None = None  # the session's frame index of the first frame received (0: watched from its start)
    received: int = 0
    lost: int = 0
    skipped: int = 0
    resyncs: int = 0
    connections: int = 0
    audio_blocks: int = 0
    audio_device: str | None = None
    audio_underruns: int = 0  # device callbacks flagged "output underflow" (AudioOut.underruns)
    delivery_ms: list[float] = field(default_factory=list)
    saved_sound: Path | None = None  # the WAV written for save_sound (None: none asked, or no description came)
    rest_steps: int = 0  # images drawn easing the face to rest after sessions ended (REST_EASE_S each)
    interrupted: bool = False  # stopped by Ctrl-C (KeyboardInterrupt), not by --duration or the window's close


class Playout:
    """due(m) = m + offset (s, perf_counter clock); see the module docstring."""

    def __init__(self, buffer_s: float) -> None:
        self.buffer_s = buffer_s
        self.offset: float | None = None
        self.resyncs = 0

    def arrive(self, media_time: float, arrival: float) -> float:
        if self.offset is None:
            self.offset = arrival - media_time + self.buffer_s
        due = media_time + self.offset
        if arrival > due + 0.001:
            self.offset += arrival - due + self.buffer_s / 2
            self.resyncs += 1
            due = media_time + self.offset
        return due


class AudioOut:
    """Plays relayed blocks at their due times through sounddevice (None device: silent).

    ``add``/``reset`` come from the receiver thread, the callback from PortAudio's; ``keep_played``
    keeps every buffer handed to the device (``played()``: what the device was given, silence
    included), for ``facecast view --save-sound``."""

    def __init__(self, playout: Playout, *, keep_played: bool = False) -> None:
        self.rate: int | None = None  # Hz, from the first description (open)
        self.playout = playout
        self.lock = threading.Lock()
        self.blocks: list[tuple[int, np.ndarray]] = []  # (first media sample, samples (n,) float32)
        self.received = 0  # audio blocks added
        self.stream = None
        self.device: str | None = None
        self.error = ""
        # Callbacks PortAudio flagged "output underflow": the device ran dry (the callback missed its
        # turn, e.g. starved of the GIL). Through ALSA's PulseAudio plugin each one is followed by
        # 1.2-2 s in which the device asks for nothing, so is heard as that much silence; the
        # callback then resumes at the right media time (the stream clock stays locked to
        # perf_counter), measured on a PulseAudio null sink (docs/service.md, "The Python viewer's sound").
        self.underruns = 0
        self._clock_delta = 0.0  # stream clock - perf_counter
        self._played: list[np.ndarray] | None = [] if keep_played else None

    def open(self, rate_hz: int) -> None:
        """Start the output stream on the default device at ``rate_hz``; stays silent when there is none."""
        self.rate = rate_hz
        try:
            import sounddevice as sd  # PortAudio is loaded here: OSError when it is missing
        except (ImportError, OSError) as exc:
            self.error = str(exc)
            return
        try:
            info = sd.query_devices(kind="output")
            # PortAudio's "high" latency: through ALSA's PulseAudio plugin "low" underran and then
            # stalled under load (silence while frames went on); the DAC time below accounts for
            # whatever latency the device has, so sync does not depend on it.
            stream = sd.OutputStream(
                samplerate=self.rate, channels=1, dtype="float32", callback=self._callback, latency="high"
            )
            stream.start()
            self.stream = stream
            self._clock_delta = stream.time - time.perf_counter()
            self.device = str(info["name"])
        except (sd.PortAudioError, ValueError) as exc:  # no device, or no default output device
            self.stream = None
            self.error = str(exc)

    def add(self, media_time: float, samples: np.ndarray, rate_hz: int) -> None:
        """Keep one relayed block (media time in s, samples (n,) at ``rate_hz``) until it is played."""
        with self.lock:
            self.received += 1
            self.blocks.append((int(round(media_time * rate_hz)), samples))
            if len(self.blocks) > 400:  # ~8 s of 20 ms blocks: older ones have been played
                del self.blocks[:100]

    def reset(self) -> None:
        with self.lock:
            self.blocks.clear()

    def _callback(self, out: np.ndarray, frames: int, t, status) -> None:
        out.fill(0)
        if status.output_underflow:
            self.underruns += 1
        offset = self.playout.offset
        if offset is None:
            return
        heard_at = t.outputBufferDacTime - self._clock_delta  # perf_counter time of out[0]
        first = int(round((heard_at - offset) * self.rate))  # media sample heard then
        with self.lock:
            for start, block in self.blocks:
                lo, hi = max(first, start), min(first + frames, start + len(block))
                if hi > lo:
                    out[lo - first : hi - first, 0] = block[lo - start : hi - start]
        if self._played is not None:
            self._played.append(out[:, 0].copy())

    def played(self) -> np.ndarray:
        """Every buffer given to the device so far, in order (float32, at ``rate``); needs keep_played."""
        if self._played is None:
            raise ValueError("AudioOut(keep_played=False) keeps nothing")
        return np.concatenate(self._played) if self._played else np.zeros(0, np.float32)

    def close(self) -> None:
        if self.stream is not None:
            self.stream.stop()
            self.stream.close()


class _Receiver(threading.Thread):
    """Connects, forwards ("desc", d) / ("msg", Message, arrival) / ("closed", code, reason) /
    ("error", text) into ``inbox``, audio blocks into ``audio`` directly (cleared at each new
    connection before any of its blocks); reconnects whenever the session ends or the server goes
    away; :meth:`close` cancels it from another thread."""

    def __init__(self, cfg: ViewerStreamConfig, inbox: queue.SimpleQueue, audio: AudioOut) -> None:
        super().__init__(name="facecast-view-rx", daemon=True)
        self.cfg, self.inbox, self.audio = cfg, inbox, audio
        self.loop: asyncio.AbstractEventLoop | None = None
        self.task: asyncio.Task | None = None
        self.ready = threading.Event()

    def run(self) -> None:
        # asyncio.Runner, not a bare loop: on closing it cancels and finishes what is still pending (a connection's
        # keepalive task), where a loop closed over it printed "Task was destroyed but it is pending!".
        with asyncio.Runner() as runner, contextlib.suppress(asyncio.CancelledError):
            self.loop = runner.get_loop()
            runner.run(self._main())

    def _own_task(self) -> None:
        self.task = asyncio.current_task()
        self.ready.set()

    def close(self) -> None:
        self.ready.wait(2)
        if self.loop is not None and self.task is not None and not self.loop.is_closed():
            with contextlib.suppress(RuntimeError):  # the loop closed in between
                self.loop.call_soon_threadsafe(self.task.cancel)
        self.join(3)

    async def _main(self) -> None:
        self._own_task()
        cfg, inbox = self.cfg, self.inbox
        # Each attempt is held by the server for cfg.wait_s. Refused at once (a server that holds nobody): None,
        # every RETRY_S for cfg.wait_s (nothing is replayed: a slower first wait misses the first frames); then,
        # and after each session, a back-off (REWATCH_MAX_S)
        waits: Iterator[float] | None = None
        while True:
            try:
                v = await connect_viewer(cfg, waits=waits)
            except ClientError as exc:
                inbox.put(("error", str(exc)))
                waits = waits or backoff(REWATCH_MAX_S)
                await asyncio.sleep(next(waits))
                continue
            waits = backoff(REWATCH_MAX_S)  # the wait for the session to come back starts fast again
            # A new connection's media times start again: the old blocks must not sound for them.
            self.audio.reset()
            rate = int((v.description.get("audio") or {}).get("rate_hz", 16000))
            inbox.put(("desc", v.description))
            try:
                async for m in v:
                    if m.kind == P.KIND_AUDIO:
                        self.audio.add(m.media_time, m.values, rate)
                    else:
                        inbox.put(("msg", m, time.perf_counter()))
            finally:
                await v.__aexit__(None, None, None)
            inbox.put(("closed", v.close_code, v.close_reason))
            await asyncio.sleep(0.2)


def run_window(
    cfg: ViewerStreamConfig,
    mesh: HeadMesh,
    *,
    config: RenderConfig = RenderConfig(margin=1.25),
    buffer_s: float = 0.08,
    duration_s: float | None = None,
    screenshot=None,
    save_sound=None,
    status=print,
) -> LiveStats:
    """Open a window and show the session live until it is closed (or ``duration_s`` seconds after
    the first frame); ``screenshot``: PNG path for the last image shown, written however the window stops
    (Ctrl-C included); ``save_sound``: WAV path for the sound as given to the device (silence included).
    ClientError without a display."""
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ClientError("no display (DISPLAY is unset): use --record OUT.mp4, or open the server's URL in a browser")
    try:
        import glfw
        import moderngl
    except ImportError as exc:
        raise ClientError(f"the live window needs glfw and moderngl: {exc}") from None
    if not glfw.init():
        raise ClientError("cannot open a window: glfw could not initialise the display")
    stats = LiveStats()
    inbox: queue.SimpleQueue = queue.SimpleQueue()
    playout = Playout(buffer_s)
    audio = AudioOut(playout, keep_played=save_sound is not None)
    rx = _Receiver(cfg, inbox, audio)
    renderer: HeadRenderer | None = None
    image: np.ndarray | None = None  # (height, width, 3) uint8: the last image drawn (for the screenshot)
    last_error = None
    try:
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, 3)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, 3)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.RESIZABLE, glfw.FALSE)  # the image is copied 1:1 into the window
        win = glfw.create_window(config.width, config.height, f"facecast: {cfg.session}", None, None)
        if not win:
            raise ClientError("cannot open a window (no OpenGL 3.3 visual on this display)")
        glfw.make_context_current(win)
        glfw.swap_interval(0)  # frames are paced by their due times, not the monitor
        wctx = moderngl.create_context()
        screen_tex = wctx.texture((config.width, config.height), 3)
        screen_fbo = wctx.framebuffer(color_attachments=[screen_tex])
        neutral = np.asarray(mesh.vertices, dtype=np.float32)
        moving = np.zeros(0, np.int64)
        pending: list[tuple[float, P.Message]] = []
        last_index = -1
        first_shown: float | None = None
        last_drawn: np.ndarray | None = None  # the deltas (3 k,) of the frame on screen
        # After a session's end its last frames are shown, then the face eases to rest: a session cut off
        # mid-word used to leave its open mouth in the window until it came back. to_rest: the session
        # closed, the easing starts once the pending frames are drawn; rest: (start time, deltas eased);
        # rest_deltas: the deltas of the rest pose (the description's rest_values: a head resting through its
        # own targets, lips modelled apart, rests away from its neutral).
        to_rest = False
        rest: tuple[float, np.ndarray] | None = None
        rest_deltas = np.zeros(0, np.float32)

        def draw(values: np.ndarray) -> None:
            nonlocal image, last_drawn
            assert renderer is not None  # frames are drawn once a description made it
            v = neutral.copy()
            v[moving] += values.reshape(-1, 3)
            with renderer.ctx:
                image = renderer.render(v)
            glfw.make_context_current(win)
            screen_tex.write(np.ascontiguousarray(image[::-1]).tobytes())  # GL rows go bottom-up
            wctx.copy_framebuffer(wctx.screen, screen_fbo)
            glfw.swap_buffers(win)
            last_drawn = values

        rx.start()
        while not glfw.window_should_close(win):
            glfw.poll_events()
            while True:
                try:
                    item = inbox.get_nowait()
                except queue.Empty:
                    break
                if item[0] == "desc":
                    d = item[1]
                    if (d.get("head") or {}).get("vertex_count") != len(neutral):
                        raise ClientError("the server's head changed; restart facecast view")
                    moving = np.asarray(d["head"]["moving_vertices"], dtype=np.int64)
                    rest_deltas = np.asarray(d.get("rest_values") or np.zeros(3 * len(moving)), dtype=np.float32)
                    if renderer is None:
                        c, ax, size = framing(neutral, moving)
                        renderer = HeadRenderer(
                            mesh, centre=c, axes=ax, size=size, config=replace(config, backend=None)
                        )
                        # The first draw compiles the shaders while holding the GIL (~0.4 s under
                        # load): done before the sound starts, whose callback needs the GIL every
                        # few ms (a starved callback underruns, and ALSA's PulseAudio plugin then
                        # stays silent for about 2 s).
                        with renderer.ctx:
                            renderer.render(neutral)
                        glfw.make_context_current(win)
                    if last_drawn is None:
                        draw(rest_deltas)  # the head at rest until the first frame (was: an empty window)
                    if audio.rate is None and d.get("audio"):
                        audio.open(int(d["audio"]["rate_hz"]))
                        stats.audio_device = audio.device
                        status(
                            f"facecast view: sound {'on ' + audio.device if audio.device else 'off (no output device)'}"
                        )
                    playout.offset, last_index = None, -1
                    pending.clear()
                    to_rest, rest = False, None
                    stats.connections += 1
                    status(f"facecast view: watching {cfg.session!r}")
                elif item[0] == "msg":
                    m, arrival = item[1], item[2]
                    if last_index >= 0 and m.index > last_index + 1:
                        stats.lost += m.index - last_index - 1
                    last_index = m.index
                    stats.first_index = m.index if stats.first_index is None else stats.first_index
                    stats.received += 1
                    stats.delivery_ms.append(1000 * (time.time() - m.send_time))
                    pending.append((playout.arrive(m.media_time, arrival), m))
                elif item[0] == "closed":
                    status(f"facecast view: session closed ({item[1]} {item[2]}); waiting for it to come back")
                    to_rest = last_drawn is not None
                elif item[0] == "error" and item[1] != last_error:
                    last_error = item[1]
                    status(f"facecast view: {item[1]}; retrying")
            now = time.perf_counter()
            show = None
            while pending and pending[0][0] <= now:
                if show is not None:
                    stats.skipped += 1
                show = pending.pop(0)[1]
            if show is not None and renderer is not None:
                draw(show.values)
                stats.shown += 1
                first_shown = first_shown or now
            elif (to_rest or rest is not None) and not pending and last_drawn is not None:
                if rest is None:
                    rest, to_rest = (now, np.array(last_drawn, dtype=np.float32)), False
                f = min(1.0, (now - rest[0]) / REST_EASE_S)
                k = np.float32(1 - f * f * (3 - 2 * f))  # smoothstep: no jump at either end
                draw(rest_deltas + (rest[1] - rest_deltas) * k)
                stats.rest_steps += 1
                if f >= 1.0:
                    rest = None
                else:
                    glfw.wait_events_timeout(0.016)  # about 60 steps a second, not a busy loop
            elif show is None:
                glfw.wait_events_timeout(0.004)
            if duration_s is not None and first_shown is not None and now - first_shown >= duration_s:
                break
    except KeyboardInterrupt:  # Ctrl-C, the usual way out of a window: the caller prints its summary as for --duration
        stats.interrupted = True
    finally:
        stats.resyncs = playout.resyncs
        stats.audio_blocks = audio.received
        stats.audio_underruns = audio.underruns
        rx.close()
        audio.close()
        # here, not after the loop: a window is mostly stopped with Ctrl-C (KeyboardInterrupt), which wrote no PNG
        if screenshot is not None and image is not None:
            from PIL import Image

            Image.fromarray(image).save(screenshot)
        if save_sound is not None and audio.rate is not None:
            from assets.audio import write_wav

            stats.saved_sound = write_wav(save_sound, audio.played(), audio.rate)
        if renderer is not None:
            renderer.close()
        glfw.terminate()
    return stats

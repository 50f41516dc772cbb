"""Offline speech: WAV in -> words (pocketsphinx, with the dialogue's grammar), words -> WAV
(espeak-ng, the simulated Pepper's voice).

Why these two: both run on the machine, with no service to reach and no model to download (the
``pocketsphinx`` wheel carries its US English model; Debian's ``espeak-ng`` speaks). The
recogniser listens with :mod:`gateway.dialogue.grammar`'s grammar; it is not thread-safe, so one
utterance is decoded at a time (20-150 ms each).
"""

from __future__ import annotations

import io
import logging
import os
import shutil
import subprocess
import threading
import time
import wave
from dataclasses import dataclass
from typing import Any

import numpy as np

from gateway.dialogue.grammar import Grammar, spell_out

log = logging.getLogger(__name__)
RATE = 16_000  # the acoustic model's sample rate
_PAD = np.zeros(RATE // 4, dtype="<i2")  # a quarter second of silence each side: the decoder finds the ends


class AudioInvalid(ValueError):
    """Audio the gateway cannot listen to; the message names the problem."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.message = message


class SpeechUnavailable(RuntimeError):
    """The recogniser or the synthesiser is not installed on this machine."""


class VoiceUnknown(ValueError):
    """espeak-ng has no such voice."""


@dataclass(frozen=True)
class Recognised:
    text: str
    confidence: float
    duration_s: float
    latency_ms: float


def read_wav(data: bytes, max_seconds: float) -> tuple[np.ndarray, float]:
    """16-bit PCM WAV bytes -> mono samples at 16 kHz and the audio's length in seconds;
    :class:`AudioInvalid` for anything else (not WAV, compressed, empty, too long)."""
    if not data:
        raise AudioInvalid("audio: empty (no bytes)")
    if data[:4] != b"RIFF" or data[8:12] != b"WAVE":
        raise AudioInvalid("audio: not a WAV file (it does not start with a RIFF/WAVE header)")
    try:
        with wave.open(io.BytesIO(data)) as w:
            width, channels, rate, frames = w.getsampwidth(), w.getnchannels(), w.getframerate(), w.getnframes()
            raw = w.readframes(frames)
    except (wave.Error, EOFError) as exc:
        raise AudioInvalid(f"audio: not a readable WAV file ({exc}); send 16-bit PCM") from None
    if width != 2:
        raise AudioInvalid(f"audio: {8 * width}-bit samples; send 16-bit PCM WAV")
    if not rate or not raw:
        raise AudioInvalid("audio: the WAV file holds no samples")
    seconds = len(raw) / (2 * channels * rate)
    if seconds > max_seconds:
        raise AudioInvalid(f"audio: {seconds:.1f} s long, at most {max_seconds:g} s (dialogue.max_audio_s)")
    samples = np.frombuffer(raw[: len(raw) - len(raw) % (2 * channels)], dtype="<i2")
    if channels > 1:
        samples = samples.reshape(-1, channels).mean(axis=1)
    return _resample(samples, rate), seconds


def _resample(samples: np.ndarray, rate: int) -> np.ndarray:
    if rate == RATE:
        return samples.astype("<i2")
    count = max(1, int(len(samples) * RATE / rate))
    positions = np.linspace(0, len(samples) - 1, count)
    return np.interp(positions, np.arange(len(samples)), samples.astype(np.float64)).astype("<i2")


class Recogniser:
    """pocketsphinx with the dialogue's grammar (rebuilt when the grammar changes)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._decoder: Any = None
        self._grammar_key: int | None = None
        self.spelled: dict[str, str] = {}  # words given a pronunciation from their letters

    def _ensure(self, grammar: Grammar) -> Any:
        if self._decoder is None:
            try:
                from pocketsphinx import Decoder, get_model_path
            except ImportError as exc:
                raise SpeechUnavailable("speech recognition needs the pocketsphinx package") from exc
            model = get_model_path()
            self._decoder = Decoder(hmm=os.path.join(model, "en-us", "en-us"), lm=None, logfn=os.devnull,
                                    dict=os.path.join(model, "en-us", "cmudict-en-us.dict"))
        if self._grammar_key != grammar.key:
            self._load(grammar)
        return self._decoder

    def _load(self, grammar: Grammar) -> None:
        decoder = self._decoder
        given = dict(grammar.given)
        missing = sorted(w for w in grammar.words if w in given or decoder.lookup_word(w) is None)
        entries: list[tuple[str, str]] = []
        for word in missing:
            phones = given.get(word) or spell_out(word)
            if word not in given:
                self.spelled[word] = phones
            # alternatives are the dictionary's word(2), word(3)...: the recogniser answers the word
            entries += [(word if n == 0 else f"{word}({n + 1})", alt.strip()) for n, alt in enumerate(phones.split("|"))]
        for i, (entry, phones) in enumerate(entries):
            try:
                decoder.add_word(entry, phones, i == len(entries) - 1)
            except RuntimeError:
                log.warning("the recogniser refused the pronunciation %r of %r", phones, entry)
        decoder.add_jsgf_string("dialogue", grammar.jsgf)
        decoder.activate_search("dialogue")
        self._grammar_key = grammar.key

    def recognise(self, samples: np.ndarray, grammar: Grammar) -> Recognised:
        """The words heard in ``samples`` (16 kHz mono), "" when nothing in the grammar fits."""
        audio = np.concatenate([_PAD, samples.astype("<i2"), _PAD]).tobytes()
        with self._lock:
            decoder = self._ensure(grammar)
            started = time.perf_counter()
            decoder.start_utt()
            # full_utt=False: with True, pocketsphinx's grammar search ends without a result on
            # whole sentences of synthetic speech ("can i have a coffee" -> nothing)
            decoder.process_raw(audio, False, False)
            decoder.end_utt()
            hyp = decoder.hyp()
            latency = (time.perf_counter() - started) * 1000
            text = hyp.hypstr if hyp is not None else ""
            confidence = float(decoder.get_logmath().exp(hyp.prob)) if hyp is not None else 0.0
        return Recognised(text, round(confidence, 4), len(samples) / RATE, round(latency, 1))


def espeak_available() -> bool:
    return shutil.which("espeak-ng") is not None


def synthesise(text: str, voice: str = "en-us", speed: int = 160, timeout_s: float = 20.0) -> bytes:
    """``text`` spoken by espeak-ng as WAV bytes (the simulated Pepper; tests' customers)."""
    exe = shutil.which("espeak-ng")
    if exe is None:
        raise SpeechUnavailable("speech synthesis needs espeak-ng (Debian: apt-get install espeak-ng)")
    # the text goes in on stdin: text that starts with "-" must never be read as an option
    done = subprocess.run([exe, "-v", voice, "-s", str(int(speed)), "--stdout"], input=text.encode("utf-8"),
                          capture_output=True, timeout=timeout_s, check=False)
    problem = done.stderr.decode(errors="replace").strip()[:200]
    if "voice does not exist" in problem:
        raise VoiceUnknown(f"voice: espeak-ng has no voice {voice!r} (see espeak-ng --voices)")
    if done.returncode != 0 or not done.stdout.startswith(b"RIFF"):
        raise SpeechUnavailable(f"espeak-ng failed: {problem}")
    return _fix_stream_header(done.stdout)


def _fix_stream_header(data: bytes) -> bytes:
    """espeak-ng writes to a pipe with unknown sizes in the header (0xFFFFFFFF): set the real ones."""
    if len(data) < 44 or data[40:44] not in (b"\xff\xff\xff\xff", b"\x00\x00\x00\x00"):
        return data
    body = len(data) - 44
    return data[:4] + (36 + body).to_bytes(4, "little") + data[8:40] + body.to_bytes(4, "little") + data[44:]

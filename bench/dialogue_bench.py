"""Spoken dialogue: recognition latency and accuracy of the dialogue's grammar on espeak-ng voices
against pocketsphinx's open language model, and the latency of a text turn (words -> rules ->
Pepper's answer) in a real gateway.

    .venv/bin/python bench/dialogue_bench.py [--orders 100] [--voices en-us,en-us+f3,en] [--speeds 140,175]
                                            [--open-orders 100] [--turns 200] [--write-docs]

Orders are drawn (seeded) from the shipped menu (the ontology's Beverage individuals) in the
phrasings customers use ("can i have two green teas", "three cups of hojicha please", ...); each is
spoken by espeak-ng in every voice and speed. "Words" counts an exact transcript (a/an alike);
"order" counts the drink and the number the gateway makes of the transcript (what matters).
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from gateway.dialogue import grammar as grammar_mod  # noqa: E402
from gateway.dialogue import menu as menu_mod  # noqa: E402
from gateway.dialogue import speech, words  # noqa: E402
from report import machine_note, write_section  # noqa: E402

NUMBERS = ["one", "two", "three", "four", "five"]
PHRASES = ["{n} {d} please", "can i have {n} {d}", "i would like {n} {d}", "{n} cups of {s}",
           "could i have {n} {d} please", "{n} {d}"]


def orders(menu: menu_mod.Menu, count: int, seed: int = 7) -> list[tuple[str, str, int]]:
    """(sentence, drink label, cups) drawn from the menu."""
    rng = random.Random(seed)
    out = []
    for _ in range(count):
        drink = rng.choice(menu.drinks)
        cups = rng.randint(1, 5)
        said = drink.plural if cups > 1 else drink.label
        sentence = rng.choice(PHRASES).format(n=NUMBERS[cups - 1], d=said, s=drink.label)
        out.append((sentence, drink.label, cups))
    return out


def open_model_decoder():
    from pocketsphinx import Decoder, get_model_path

    model = get_model_path()
    return Decoder(hmm=os.path.join(model, "en-us", "en-us"), lm=os.path.join(model, "en-us", "en-us.lm.bin"),
                   dict=os.path.join(model, "en-us", "cmudict-en-us.dict"), logfn=os.devnull)


def decode_open(decoder, samples) -> tuple[str, float]:
    import numpy as np

    audio = np.concatenate([speech._PAD, samples, speech._PAD]).tobytes()
    started = time.perf_counter()
    decoder.start_utt()
    decoder.process_raw(audio, False, False)
    decoder.end_utt()
    hyp = decoder.hyp()
    return (hyp.hypstr if hyp else ""), (time.perf_counter() - started) * 1000


def recognition(menu, gram, sample, voices, speeds, open_orders: int) -> list[dict]:
    recogniser = speech.Recogniser()
    opened = open_model_decoder() if open_orders else None
    rows = []
    for voice in voices:
        for speed in speeds:
            stats = {"grammar": [0, 0, []], "open": [0, 0, []]}
            for i, (sentence, drink, cups) in enumerate(sample):
                samples, _ = speech.read_wav(speech.synthesise(sentence, voice, speed), 30)
                got = recogniser.recognise(samples, gram)
                _score(stats["grammar"], got.text, got.latency_ms, sentence, drink, cups, menu)
                if opened is not None and i < open_orders:
                    text, ms = decode_open(opened, samples)
                    _score(stats["open"], text, ms, sentence, drink, cups, menu)
            for kind, (exact, right, lat) in stats.items():
                if lat:
                    rows.append({"voice": voice, "speed": speed, "decoder": kind, "n": len(lat), "words": exact / len(lat),
                                 "order": right / len(lat), "p50": statistics.median(lat),
                                 "p95": sorted(lat)[max(0, int(len(lat) * 0.95) - 1)]})
    return rows


def _score(acc: list, text: str, ms: float, sentence: str, drink: str, cups: int, menu) -> None:
    norm = lambda s: " ".join(words.tokens(s)).replace(" an ", " a ")  # noqa: E731
    acc[0] += norm(text) == norm(sentence)
    heard = words.hear(text, menu)
    acc[1] += bool(heard.drink and heard.drink.label == drink and heard.count == cups)
    acc[2].append(ms)


def turn_latency(turns: int, with_store: bool = False) -> dict:
    """Text turns through the gateway's engine (a session per conversation); the conversations
    in memory (one process: the engine, the knowledge and the dialogue service alone), or
    ``with_store`` in a real gateway over the Information State (an embedded SecantusDB), as
    several processes share them (read, run, write over the rev read, the decision noted)."""
    import tempfile

    from gateway.config import Settings

    settings = Settings.model_validate({"data_dir": "/tmp/printeps-dialogue-bench", "streams": {"queries_dir": None}})
    with tempfile.TemporaryDirectory(prefix="bench-dialogue-") as tmpdir:
        db = store = None
        closers = []
        if with_store:
            from gateway.app import build_gateway
            from gateway.store.embedded import EmbeddedMongo
            from gateway.store.store import InformationState

            db = EmbeddedMongo(Path(tmpdir) / "mongo")
            store = InformationState(db.start(), "dialogue_bench", Path(tmpdir) / "journal", backend="embedded")
            gateway = build_gateway(settings, rest=False, ros=False, warm_up=False, store=store)
            d = gateway.dialogue
            closers.append(gateway.close)
        else:
            d = _dialogue_in_memory(settings)
            closers.append(d.close)
        try:
            for i in range(20):  # warm-up
                d.turn(f"w{i}", text="two green teas please")
            times = []
            for i in range(turns):
                started = time.perf_counter()
                d.turn(f"b{i % 50}", text=["two green teas please", "no make that coffee", "yes"][i % 3])
                times.append((time.perf_counter() - started) * 1000)
            return {"n": turns, "p50": statistics.median(times), "p95": sorted(times)[int(len(times) * 0.95) - 1],
                    "mean": statistics.fmean(times)}
        finally:
            for close in closers:
                close()
            if store is not None:
                store.close()
            if db is not None:
                db.stop()


def _dialogue_in_memory(settings):
    """The dialogue service over an engine and a knowledge base on an in-memory catalog, seeded
    from the repository's folders as a gateway seeds them (conversations kept in memory)."""
    from gateway.base import jvm
    from gateway.dialogue.service import DialogueService
    from gateway.engine import Engine
    from gateway.ontology.knowledge import KnowledgeBase
    from gateway.runtime.transfer import seed_folders

    jvm.start(settings.jvm)
    engine = Engine(settings)
    knowledge = KnowledgeBase()
    folders = seed_folders(settings)
    for service in (knowledge, engine):
        for folder in folders[service.kind]:
            service.seed(folder)
        service.load()
    return DialogueService(engine, knowledge, settings.dialogue)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--orders", type=int, default=100)
    ap.add_argument("--voices", default="en-us,en-us+f3,en")
    ap.add_argument("--speeds", default="140,175")
    ap.add_argument("--turns", type=int, default=200)
    ap.add_argument("--open-orders", type=int, default=100,
                    help="how many of the orders the open language model decodes too (it is 10x slower; 0: none)")
    ap.add_argument("--write-docs", action="store_true")
    args = ap.parse_args()
    note = machine_note()
    ttl = (ROOT / "ontology" / "teahouse.ttl").read_text()
    menu = menu_mod.read_menu(ttl, "http://printeps.org/cafe/entrance/")
    files = {p.name: p.read_text() for p in (ROOT / "rules" / "drl" / "dialogue").glob("*.dslr")}
    gram = grammar_mod.build(files, menu)
    sample = orders(menu, args.orders)
    rows = recognition(menu, gram, sample, args.voices.split(","), [int(s) for s in args.speeds.split(",")],
                       args.open_orders)
    turn = turn_latency(args.turns) if args.turns else None
    shared = turn_latency(args.turns, with_store=True) if args.turns else None
    lines = ["## Spoken dialogue", "",
             f"`bench/dialogue_bench.py --orders {args.orders} --voices {args.voices} --speeds {args.speeds} "
             f"--open-orders {args.open_orders} --turns {args.turns}` ({note}). Orders drawn from the menu in customers' phrasings, spoken by "
             "espeak-ng; *words*: exact transcript (a/an alike); *order*: the drink and number the gateway "
             "makes of it. *grammar*: the dialogue's JSGF grammar (rules' sentences + menu); *open*: "
             "pocketsphinx's US English language model.", "",
             "| voice | speed (wpm) | decoder | utterances | words right | order right | p50 ms | p95 ms |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['voice']} | {r['speed']} | {r['decoder']} | {r['n']} | {r['words']:.0%} | {r['order']:.0%} "
                     f"| {r['p50']:.0f} | {r['p95']:.0f} |")
    if turn:
        lines += ["", f"Text turn (words → Utterance → dialogue rules in the conversation's session → Pepper's "
                      f"answer, decision announced; conversations in memory): p50 {turn['p50']:.1f} ms, p95 {turn['p95']:.1f} ms, "
                      f"mean {turn['mean']:.1f} ms over {turn['n']} turns."]
    if shared:
        lines += ["", f"The same turns with the conversations in the Information State (embedded SecantusDB; "
                      f"what lets any gateway process continue a conversation): p50 {shared['p50']:.1f} ms, "
                      f"p95 {shared['p95']:.1f} ms, mean {shared['mean']:.1f} ms over {shared['n']} turns."]
    text = "\n".join(lines) + "\n"
    print(text)
    if args.write_docs:
        write_section("## Spoken dialogue", text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

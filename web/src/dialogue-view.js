// The Dialogue view: type, record or upload what a customer says at a table, and see what the
// gateway heard, what the understanding rules made of it (intent and slots), the state of the
// conversation and Pepper's answer — which can be played in the simulated Pepper's voice.
// Every turn is a decision (linked). The rules themselves are the `dialogue` rule set in Rules.

import "./dialogue-view.css";
import { h, fill } from "./dom.js";
import { api, getToken } from "./api.js";

const STATE_WORDS = { ordering: "taking the order", confirming: "waiting for a yes or no", ordered: "order sent to the kitchen", ended: "ended" };

export async function showDialogue(main, ctx) {
  ctx.hideSidebar();
  const conversationEl = h("input", { type: "text", class: "conversation", value: "table1", "aria-label": "Conversation (table)" });
  const textEl = h("input", { type: "text", placeholder: "two green teas, please", "aria-label": "What the customer says" });
  const fileEl = h("input", { type: "file", accept: ".wav,audio/wav", "aria-label": "Upload a WAV file", "data-testid": "dialogue-wav" });
  const recordEl = h("button", { type: "button", class: "secondary" }, "● Record");
  const statusEl = h("div", { "data-testid": "dialogue-status", role: "status" });
  const transcriptEl = h("ol", { class: "transcript", "data-testid": "dialogue-transcript" });
  const menuEl = h("p", { class: "menu muted", "data-testid": "dialogue-menu" });

  const send = async (body, said) => {
    const conversation = conversationEl.value.trim() || "table1";
    fill(statusEl, h("span", { class: "muted" }, "Pepper is listening…"));
    try {
      const turn = await api("POST", "/api/dialogue/turns", { conversation, ...body });
      fill(statusEl);
      transcriptEl.prepend(turnItem(turn, said, ctx));
    } catch (err) {
      fill(statusEl, h("div", { class: "message error", role: "alert" }, `Not taken: ${err.message}`));
    }
  };
  const form = h("form", {
    class: "turn-form", onsubmit: (e) => {
      e.preventDefault();
      if (textEl.value.trim()) send({ text: textEl.value }, textEl.value);
      textEl.value = "";
    },
  },
  h("label", {}, "Table", conversationEl), h("label", {}, "The customer says", textEl),
  h("button", { type: "submit" }, "Say"), recordEl, h("label", {}, "or a WAV file", fileEl));

  fileEl.addEventListener("change", async () => {
    const file = fileEl.files && fileEl.files[0];
    if (file) await send({ audio: await base64(await file.arrayBuffer()) }, `(audio: ${file.name})`);
    fileEl.value = "";
  });
  recordEl.addEventListener("click", () => record(recordEl, (wav) => send({ audio: base64Sync(wav) }, "(recorded)"), statusEl));

  fill(main, h("section", { class: "dialogue" },
    h("div", { class: "title-row" }, h("h1", {}, "Dialogue")),
    h("p", { class: "hint" }, "What a customer says at a table goes through the dialogue rules (Rules › dialogue): what they mean, what it does to the order, and what Pepper answers. Audio is recognised offline with a grammar made from those rules and the menu."),
    form, statusEl, menuEl, transcriptEl));
  try {
    const menu = await api("GET", "/api/dialogue/menu");
    fill(menuEl, "On the menu (the ontology's Beverage individuals): ", menu.drinks.map((d) => d.label).join(", "));
  } catch (err) {
    fill(menuEl, `The menu cannot be read: ${err.message}`);
  }
  textEl.focus();
  return {};
}

/** One turn: what was said and heard, the intent and slots, the state, Pepper's answer. */
function turnItem(turn, said, ctx) {
  const slots = turn.slots || {};
  const answer = (turn.says || []).join(" ");
  return h("li", { "data-testid": "dialogue-turn" },
    h("div", { class: "said" }, `Customer at ${turn.table}: ${said}`),
    h("div", {}, "Heard: ", h("q", { "data-testid": "heard" }, turn.heard || "(nothing)"),
      turn.confidence !== undefined ? h("span", { class: "muted" }, ` (confidence ${turn.confidence})`) : null),
    h("div", { class: "slots" },
      h("span", { "data-testid": "intent" }, `Intent: ${turn.intent}`),
      h("span", { "data-testid": "slots" }, `Drink: ${slots.drink || "—"} · Cups: ${slots.cups || "—"}`),
      h("span", { "data-testid": "state" }, `Conversation: ${STATE_WORDS[turn.state] || turn.state}`),
      h("a", { href: ctx.href("decisions", turn.decision_id) }, "decision")),
    h("div", { class: "pepper" }, "Pepper: ", h("span", { "data-testid": "pepper-says" }, answer || "(nothing)"),
      answer ? h("button", { type: "button", class: "secondary", onclick: () => play(answer) }, "▶ Play") : null));
}

/** Pepper's answer in the simulated Pepper's voice (espeak-ng on the gateway). */
async function play(text) {
  const response = await fetch("/api/dialogue/speech", {
    method: "POST", headers: { "Content-Type": "application/json", ...(getToken() ? { Authorization: `Bearer ${getToken()}` } : {}) },
    body: JSON.stringify({ text }),
  });
  if (!response.ok) return;
  const url = URL.createObjectURL(await response.blob());
  const audio = new Audio(url);
  audio.addEventListener("ended", () => URL.revokeObjectURL(url));
  await audio.play().catch(() => URL.revokeObjectURL(url));
}

/** Record from the microphone until clicked again; hands over a 16-bit mono WAV. */
async function record(button, done, statusEl) {
  if (button.recording) {
    button.recording();
    return;
  }
  let stream;
  try {
    stream = await navigator.mediaDevices.getUserMedia({ audio: true });
  } catch (err) {
    fill(statusEl, h("div", { class: "message error", role: "alert" }, `No microphone: ${err.message}`));
    return;
  }
  const context = new AudioContext();
  const source = context.createMediaStreamSource(stream);
  const processor = context.createScriptProcessor(4096, 1, 1);
  const chunks = [];
  processor.onaudioprocess = (e) => chunks.push(new Float32Array(e.inputBuffer.getChannelData(0)));
  source.connect(processor);
  processor.connect(context.destination);
  button.textContent = "■ Stop";
  button.recording = () => {
    button.recording = null;
    button.textContent = "● Record";
    processor.disconnect();
    source.disconnect();
    stream.getTracks().forEach((t) => t.stop());
    const rate = context.sampleRate;
    context.close();
    done(wavOf(chunks, rate));
  };
}

/** Float samples -> a 16-bit PCM mono WAV file. */
function wavOf(chunks, rate) {
  const length = chunks.reduce((n, c) => n + c.length, 0);
  const buffer = new ArrayBuffer(44 + length * 2);
  const view = new DataView(buffer);
  const text = (offset, s) => [...s].forEach((ch, i) => view.setUint8(offset + i, ch.charCodeAt(0)));
  text(0, "RIFF"); view.setUint32(4, 36 + length * 2, true); text(8, "WAVE"); text(12, "fmt ");
  view.setUint32(16, 16, true); view.setUint16(20, 1, true); view.setUint16(22, 1, true);
  view.setUint32(24, rate, true); view.setUint32(28, rate * 2, true); view.setUint16(32, 2, true);
  view.setUint16(34, 16, true); text(36, "data"); view.setUint32(40, length * 2, true);
  let offset = 44;
  for (const chunk of chunks) {
    for (const x of chunk) {
      view.setInt16(offset, Math.max(-1, Math.min(1, x)) * 0x7fff, true);
      offset += 2;
    }
  }
  return buffer;
}

function base64Sync(buffer) {
  const bytes = new Uint8Array(buffer);
  let binary = "";
  for (let i = 0; i < bytes.length; i += 0x8000) binary += String.fromCharCode(...bytes.subarray(i, i + 0x8000));
  return btoa(binary);
}

async function base64(buffer) {
  return base64Sync(buffer);
}

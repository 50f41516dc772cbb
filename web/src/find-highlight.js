// Marks every occurrence of the rule list's search words in an editor, as the owner types them,
// without opening CodeMirror's own search panel. findHighlight() is the extension; setFind(view,
// text) changes what is marked.

import { Decoration, EditorView, MatchDecorator, ViewPlugin } from "@codemirror/view";
import { StateEffect, StateField } from "@codemirror/state";

const setFindEffect = StateEffect.define();

const findField = StateField.define({
  create: () => "",
  update(value, tr) {
    for (const effect of tr.effects) if (effect.is(setFindEffect)) value = effect.value;
    return value;
  },
});

const mark = Decoration.mark({ class: "cm-find-match" });

function escape(text) {
  return text.replace(/[.*+?^${}()|[\]\\]/g, "\\$&");
}

function decoratorFor(text) {
  const words = text.trim().split(/\s+/).filter(Boolean).map(escape);
  if (!words.length) return null;
  return new MatchDecorator({ regexp: new RegExp(words.join("|"), "gi"), decoration: () => mark });
}

const plugin = ViewPlugin.fromClass(class {
  constructor(view) {
    this.text = view.state.field(findField);
    this.decorator = decoratorFor(this.text);
    this.decorations = this.decorator ? this.decorator.createDeco(view) : Decoration.none;
  }

  update(update) {
    const text = update.state.field(findField);
    if (text !== this.text) {
      this.text = text;
      this.decorator = decoratorFor(text);
      this.decorations = this.decorator ? this.decorator.createDeco(update.view) : Decoration.none;
    } else if (this.decorator) {
      this.decorations = this.decorator.updateDeco(update, this.decorations);
    }
  }
}, { decorations: (v) => v.decorations });

const theme = EditorView.baseTheme({ ".cm-find-match": { backgroundColor: "#ffe58a", borderRadius: "2px" } });

/** The extension that marks the search words (none until setFind is called). */
export function findHighlight() {
  return [findField, plugin, theme];
}

/** Mark `text`'s words in `view` (empty text: no marks). */
export function setFind(view, text) {
  view.dispatch({ effects: setFindEffect.of(text) });
}

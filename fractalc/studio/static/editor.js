// The scene text's editor: a textarea over a coloured copy of its text,
// line numbers beside it, and each diagnostic marked at its line (in the
// gutter) and its columns (a wavy underline).
(() => {
  "use strict";

  const KEYWORDS = new Set(["param", "let", "material", "scene", "camera", "light", "render", "path", "preset",
    "formula", "in", "init", "final", "if", "else"]);
  // comments, strings, numbers, names (a name before "(" is a call)
  const TOKEN = /(#[^\n]*)|("[^"\n]*"?)|((?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)|([A-Za-z_][A-Za-z0-9_]*)(\s*\()?/g;
  const COLOURED_LIMIT = 400000;     // characters; a longer text is shown plain (colouring it on each key costs)

  function escapeHtml(text) {
    return text.replace(/&/g, "&amp;").replace(/</g, "&lt;").replace(/>/g, "&gt;");
  }

  function colouredHtml(text) {
    let html = "", last = 0;
    for (const m of text.matchAll(TOKEN)) {
      html += escapeHtml(text.slice(last, m.index));
      const [whole, comment, string, number, name, call] = m;
      if (comment) html += `<span class="tok-comment">${escapeHtml(comment)}</span>`;
      else if (string) html += `<span class="tok-string">${escapeHtml(string)}</span>`;
      else if (number) html += `<span class="tok-number">${number}</span>`;
      else if (KEYWORDS.has(name)) html += `<span class="tok-keyword">${name}</span>${call || ""}`;
      else if (call) html += `<span class="tok-call">${name}</span>${escapeHtml(call)}`;
      else html += name;
      last = m.index + whole.length;
    }
    return html + escapeHtml(text.slice(last));
  }

  class Editor {
    constructor(root, onInput) {
      this.root = root;
      root.innerHTML = '<div class="gutter"><pre></pre></div><div class="code"><pre class="highlight" aria-hidden="true">' +
        '</pre><textarea spellcheck="false" wrap="off" autocapitalize="off" autocomplete="off" ' +
        'aria-label="scene text"></textarea></div>';
      this.gutter = root.querySelector(".gutter");
      this.numbers = root.querySelector(".gutter pre");
      this.highlight = root.querySelector("pre.highlight");
      this.textarea = root.querySelector("textarea");
      this.diagnostics = [];
      this.lines = 0;
      this.textarea.addEventListener("input", () => { this.refresh(); onInput(this.text); });
      this.textarea.addEventListener("scroll", () => this.follow());
      this.textarea.addEventListener("keydown", (event) => this.key(event));
    }

    get text() { return this.textarea.value; }

    // Replace the text, keeping the cursor and the scroll where they were.
    setText(text) {
      if (text === this.textarea.value) return;
      const { selectionStart, selectionEnd, scrollTop, scrollLeft } = this.textarea;
      this.textarea.value = text;
      this.textarea.setSelectionRange(Math.min(selectionStart, text.length), Math.min(selectionEnd, text.length));
      this.textarea.scrollTop = scrollTop;
      this.textarea.scrollLeft = scrollLeft;
      this.refresh();
    }

    setDiagnostics(items) {
      this.diagnostics = items;
      this.refresh();
    }

    // Put the cursor at a line and column (1-based) and show it.
    focusAt(line, column) {
      const lines = this.text.split("\n");
      let offset = 0;
      for (let i = 0; i < line - 1 && i < lines.length; i++) offset += lines[i].length + 1;
      offset += column - 1;
      this.textarea.focus();
      this.textarea.setSelectionRange(offset, offset);
      const lineHeight = this.lineHeight();
      this.textarea.scrollTop = Math.max(0, (line - 3) * lineHeight);
    }

    lineHeight() {
      return parseFloat(getComputedStyle(this.textarea).lineHeight) || 19.5;
    }

    key(event) {
      if (event.key === "Tab" && !event.ctrlKey && !event.metaKey && !event.altKey) {   // four spaces, not leaving the editor
        event.preventDefault();
        document.execCommand("insertText", false, "    ");
      }
    }

    refresh() {
      const text = this.textarea.value;
      const lines = text.split("\n").length;
      if (lines !== this.lines) {
        this.lines = lines;
        this.numbers.textContent = Array.from({ length: lines }, (_, i) => i + 1).join("\n");
      }
      this.highlight.innerHTML = (text.length <= COLOURED_LIMIT ? colouredHtml(text) : escapeHtml(text)) + "\n";
      for (const old of this.gutter.querySelectorAll(".marker")) old.remove();
      const lineHeight = this.lineHeight();
      const padding = 4;
      for (const d of this.diagnostics) {
        const marker = document.createElement("div");
        marker.className = "marker";
        marker.dataset.line = d.line;
        marker.title = d.message;
        marker.style.top = `${padding + (d.line - 1) * lineHeight}px`;
        marker.style.height = `${lineHeight}px`;
        this.gutter.appendChild(marker);
        const squiggle = document.createElement("span");
        squiggle.className = "squiggle";
        squiggle.dataset.line = d.line;
        squiggle.style.top = `${padding + (d.line - 1) * lineHeight}px`;
        squiggle.style.left = `calc(8px + ${d.column - 1}ch)`;
        squiggle.style.width = `${Math.max(1, d.width)}ch`;
        this.highlight.appendChild(squiggle);
      }
      this.follow();
    }

    // The coloured copy, the numbers and the markers scroll with the textarea.
    follow() {
      this.highlight.scrollTop = this.textarea.scrollTop;
      this.highlight.scrollLeft = this.textarea.scrollLeft;
      this.gutter.scrollTop = this.textarea.scrollTop;
    }
  }

  window.Editor = Editor;
})();

// Render the formulas of every page with the KaTeX shipped in docs/assets/katex (no
// network). pymdownx.arithmatex (generic mode) leaves \( ... \) and \[ ... \] in
// <span class="arithmatex"> / <div class="arithmatex">; Material's document$ fires on
// every page load, including instant navigation.
function renderMath(body) {
  renderMathInElement(body, {
    delimiters: [
      { left: "\\(", right: "\\)", display: false },
      { left: "\\[", right: "\\]", display: true },
      { left: "$$", right: "$$", display: true }
    ],
    throwOnError: false
  });
}
if (typeof document$ !== "undefined") {
  document$.subscribe(({ body }) => renderMath(body));
} else {
  document.addEventListener("DOMContentLoaded", () => renderMath(document.body));
}

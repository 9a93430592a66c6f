// Controls for params and for block keys, built from what the server says
// of them (a param's declaration; a key's spec from the language's own key
// tables: kind, words, range, whether it is a colour).
(() => {
  "use strict";

  function element(tag, properties = {}, children = []) {
    const node = document.createElement(tag);
    Object.assign(node, properties);
    for (const child of children) node.append(child);
    return node;
  }

  function row(label, ...children) {
    return element("div", { className: "row" }, [element("label", { textContent: label, title: label }), ...children]);
  }

  // Colours are linear in the file; a colour picker shows sRGB.
  function linearToSrgb(x) {
    x = Math.min(Math.max(x, 0), 1);
    return x <= 0.0031308 ? 12.92 * x : 1.055 * Math.pow(x, 1 / 2.4) - 0.055;
  }

  function srgbToLinear(x) {
    return x <= 0.04045 ? x / 12.92 : Math.pow((x + 0.055) / 1.055, 2.4);
  }

  function colourHex(rgb) {
    return "#" + rgb.map((c) => Math.round(linearToSrgb(c) * 255).toString(16).padStart(2, "0")).join("");
  }

  function hexColour(hex) {
    return [1, 3, 5].map((i) => Number((srgbToLinear(parseInt(hex.slice(i, i + 2), 16) / 255)).toFixed(4)));
  }

  function numberInput(spec, value, onChange) {
    const input = element("input", { type: "number", step: spec.kind === "whole number" ? "1" : "any" });
    if (spec.low !== null) input.min = spec.low;
    if (spec.high !== null) input.max = spec.high;
    if (value !== null && value !== undefined) input.value = value;
    input.addEventListener("change", () => {
      if (input.value !== "" && Number.isFinite(Number(input.value))) onChange(Number(input.value));
    });
    return input;
  }

  function vectorInputs(spec, value, onChange) {
    const current = Array.isArray(value) ? value.slice() : [0, 0, 0];
    const inputs = current.map((c, i) => {
      const input = element("input", { type: "number", step: "any", value: c, className: "component" });
      input.addEventListener("change", () => {
        if (input.value === "" || !Number.isFinite(Number(input.value))) return;
        current[i] = Number(input.value);
        onChange(current.slice());
      });
      return input;
    });
    if (!spec.colour) return inputs;
    const picker = element("input", { type: "color", value: colourHex(current), title: "colour (shown in sRGB)" });
    picker.addEventListener("change", () => {
      const rgb = hexColour(picker.value);
      rgb.forEach((c, i) => { current[i] = c; inputs[i].value = c; });
      onChange(current.slice());
    });
    return [picker, ...inputs];
  }

  // One key: `set(path, value)` asks the server to write it into the text
  // (value null: back to the key's default).
  function keyControl(spec, value, path, set) {
    const reset = element("button", { className: "reset", textContent: "x", title: "remove the key (its default)" });
    reset.addEventListener("click", () => set(path, null));
    if (spec.kind === "block") {
      const on = element("input", { type: "checkbox", checked: value !== null && value !== undefined });
      on.addEventListener("change", () => set(path, on.checked ? {} : null));
      const group = element("div", { className: "group" }, [row(spec.name, on)]);
      if (on.checked) {
        for (const key of spec.keys) group.append(keyControl(key, value[key.name], [...path, key.name], set));
      }
      return group;
    }
    if (spec.kind === "file") {
      return row(spec.name, element("span", { className: "disabled-note", textContent: value || "(none)" }));
    }
    const isWord = typeof value === "string";
    const valueControls = spec.kind === "word" ? [] :
      spec.kind === "3-vector" ? vectorInputs(spec, isWord ? null : value, (v) => set(path, v)) :
        [numberInput(spec, isWord ? null : value, (v) => set(path, v))];
    if (spec.words.length === 0) return row(spec.name, ...valueControls, reset);
    // words, and a value where the key also takes one (epsilon: pixel or a number)
    const choice = element("select");
    for (const word of spec.words) choice.append(element("option", { value: word, textContent: word }));
    if (spec.kind !== "word") choice.append(element("option", { value: "", textContent: spec.kind }));
    choice.value = isWord ? value : "";
    const box = element("span", {}, valueControls);
    box.hidden = isWord;
    choice.addEventListener("change", () => {
      box.hidden = choice.value !== "";
      if (choice.value !== "") set(path, choice.value);
    });
    return row(spec.name, choice, box, reset);
  }

  // A key that an expression of params computes has no control.
  function fixedKey(spec) {
    return row(spec.name, element("span", { className: "disabled-note", textContent: "set by an expression" }));
  }

  // `computed`: a null value is one an expression computes (a material's),
  // not a key that is off or unset
  function keyControls(container, specs, values, set, computed = false) {
    for (const spec of specs) {
      const value = values[spec.name];
      container.append(computed && value === null ? fixedKey(spec) : keyControl(spec, value, [spec.name], set));
    }
  }

  // A param: a slider over its range (if it has one) and a number entry.
  function paramControl(param, value, onInput) {
    const number = element("input", { type: "number", step: "any", value, id: `param-${param.name}` });
    const controls = [];
    let slider = null;
    if (param.low !== null && param.high !== null) {
      slider = element("input", { type: "range", min: param.low, max: param.high, value,
        step: (param.high - param.low) / 1000 || "any", id: `param-${param.name}-range` });
      slider.addEventListener("input", () => { number.value = slider.value; onInput(Number(slider.value)); });
      controls.push(slider);
      number.min = param.low;
      number.max = param.high;
    }
    number.addEventListener("change", () => {
      if (number.value === "" || !Number.isFinite(Number(number.value))) return;
      if (slider) slider.value = number.value;
      onInput(Number(number.value));
    });
    controls.push(number);
    const control = row(param.name, ...controls);
    control.show = (v) => { number.value = v; if (slider) slider.value = v; };
    return control;
  }

  window.Controls = { element, row, keyControls, paramControl };
})();

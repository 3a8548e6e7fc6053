// lodconvert viewer pages, what every page script shares (before its own part): the alert box
// over the view and the rows of attributes the inspect panel shows of a clicked object.

const problem = document.getElementById("problem");

/** Show `text` in the page's alert box, over the view (null: hide it). */
function alertBox(text) {
  problem.textContent = text ?? "";
  problem.hidden = text === null;
}

const isRecord = (value) => value !== null && typeof value === "object" && !Array.isArray(value);

/** A row of `body` headed by `name` (its cell `text`, or the whole row without text). */
function addRow(body, name, text = null) {
  const row = body.insertRow();
  const header = document.createElement("th");
  header.textContent = name;
  header.scope = text === null ? "rowgroup" : "row";
  header.colSpan = text === null ? 2 : 1;
  row.append(header);
  if (text !== null) row.insertCell().textContent = text;
}

/** Whether `value` is a non-empty list of objects (a building's `parts`). */
const isRecords = (value) => Array.isArray(value) && value.length > 0 && value.every(isRecord);

/**
 * Add `attributes` to `table`: a body with a row per plain attribute (strings as they are,
 * other values as JSON), then a body per nested object, headed by its (dotted) `name`, and one
 * per object of a list of objects, headed by the list's name and its number (`parts 1`…).
 */
function addAttributes(table, attributes, name = null) {
  const body = table.createTBody();
  if (name !== null) addRow(body, name);
  const entries = Object.entries(attributes);
  const nested = ([, v]) => isRecord(v) || isRecords(v);
  for (const [key, value] of entries.filter((entry) => !nested(entry))) {
    addRow(body, key, typeof value === "string" ? value : JSON.stringify(value));
  }
  for (const [key, value] of entries.filter(nested)) {
    const dotted = name === null ? key : `${name}.${key}`;
    if (isRecord(value)) addAttributes(table, value, dotted);
    else value.forEach((item, k) => addAttributes(table, item, `${dotted} ${k + 1}`));
  }
}

// inspector HTML report: sort and filter the tables, link curves and rows. No network, no library.
(function () {
  "use strict";
  // Each table (rollouts, dataset episodes) sorts by itself and has its own filter box.
  function setUp(tableId, filterId, shownId) {
    var table = document.getElementById(tableId);
    if (!table) return;
    var body = table.tBodies[0];
    var rows = Array.prototype.slice.call(body.rows);

    function cellValue(row, col, numeric) {
      var text = row.cells[col].textContent.trim();
      if (!numeric) return text.toLowerCase();
      var v = parseFloat(text);
      return isNaN(v) ? null : v;
    }

    // Sorting: a click sorts by the column, a second click reverses; missing values ('-') stay last.
    Array.prototype.forEach.call(table.tHead.rows[0].cells, function (th, col) {
      th.addEventListener("click", function () {
        var numeric = th.classList.contains("num");
        var dir = th.getAttribute("aria-sort") === "ascending" ? -1 : 1;
        Array.prototype.forEach.call(table.tHead.rows[0].cells, function (h) { h.removeAttribute("aria-sort"); });
        th.setAttribute("aria-sort", dir === 1 ? "ascending" : "descending");
        var keyed = rows.map(function (r, i) { return [cellValue(r, col, numeric), i, r]; });
        keyed.sort(function (a, b) {
          if (a[0] === null || b[0] === null) return (a[0] === null) - (b[0] === null) || a[1] - b[1];
          if (a[0] < b[0]) return -dir;
          if (a[0] > b[0]) return dir;
          return a[1] - b[1];
        });
        rows = keyed.map(function (k) { return k[2]; });
        var frag = document.createDocumentFragment();
        rows.forEach(function (r) { frag.appendChild(r); });
        body.appendChild(frag);
      });
    });

    // Filtering: rows whose text holds every word typed.
    var filter = document.getElementById(filterId);
    var count = document.getElementById(shownId);
    filter.addEventListener("input", function () {
      var words = filter.value.toLowerCase().split(/\s+/).filter(Boolean);
      var shown = 0;
      rows.forEach(function (r) {
        var text = r.textContent.toLowerCase();
        var ok = words.every(function (w) { return text.indexOf(w) >= 0; });
        r.hidden = !ok;
        shown += ok;
      });
      count.textContent = shown;
    });
  }
  setUp("rollouts", "filter", "shown");
  setUp("episodes", "filter-episodes", "shown-episodes");

  // Highlighting: hovering a row, a curve, a dot or a legend entry lights up that rollout everywhere.
  var lit = [];
  function light(key) {
    lit.forEach(function (e) { e.classList.remove("on"); });
    lit = key === null ? [] : Array.prototype.slice.call(document.querySelectorAll('[data-key="' + key + '"]'));
    lit.forEach(function (e) { e.classList.add("on"); });
    document.body.classList.toggle("hl", lit.length > 0);
  }
  document.addEventListener("mouseover", function (ev) {
    var el = ev.target.closest ? ev.target.closest("[data-key]") : null;
    light(el ? el.getAttribute("data-key") : null);
  });
  // A click on a curve or a dot shows its row.
  document.addEventListener("click", function (ev) {
    var el = ev.target.closest ? ev.target.closest("svg [data-key]") : null;
    if (!el) return;
    var row = document.querySelector('tbody tr[data-key="' + el.getAttribute("data-key") + '"]');
    if (!row) return;
    row.hidden = false;
    row.scrollIntoView({block: "center"});
    row.classList.add("flash");
    setTimeout(function () { row.classList.remove("flash"); }, 1200);
  });
  document.documentElement.setAttribute("data-ready", "1");
})();

#!/usr/bin/python3
"""Checks an `evio sweep` HTML report the way a reader's browser sees it.

    check_html_report.py REPORT/index.html [--min-images N] [--chromium PATH]

1. Self-contained: every <img>, <script>, <link>, <iframe>, <source> and CSS url() refers to a data:
   URI or an in-page anchor (nothing that breaks when the page is mailed or moved); every image's
   data decodes and is a PNG, JPEG, GIF or SVG.
2. Rendered in headless Chromium: a copy of the page gets, first in its <head>, a probe script that
   records every script error and failed resource load (window 'error' events, capture phase), and
   after 'load' counts the images that did not decode (complete && naturalWidth > 0). Chromium's
   --dump-dom gives the DOM after load with the probe's findings; Chromium's console log (stderr)
   is searched for uncaught errors too. A page whose probe did not run fails.

Exit 0: no broken image, no script error, at least --min-images images. Exit 1 with the findings
otherwise. Exit 77 (ctest SKIP_RETURN_CODE) with a message when Chromium is not installed
(Debian package chromium).
"""
import argparse
import base64
import html.parser
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

PROBE = r"""<script>
(function () {
  var errors = [];
  window.addEventListener('error', function (e) {
    var t = e.target;
    if (t && t !== window && (t.src || t.href)) errors.push('resource failed: ' + String(t.src || t.href).slice(0, 80));
    else errors.push('script error: ' + e.message + ' at ' + e.filename + ':' + e.lineno);
  }, true);
  window.addEventListener('unhandledrejection', function (e) { errors.push('unhandled rejection: ' + e.reason); });
  window.addEventListener('load', function () {
    var broken = [];
    for (var i = 0; i < document.images.length; ++i) {
      var im = document.images[i];
      if (!im.complete || im.naturalWidth === 0) broken.push(im.alt || String(im.src).slice(0, 60));
    }
    var out = document.createElement('pre');
    out.id = 'evio-report-probe';
    out.textContent = JSON.stringify({images: document.images.length, broken: broken, errors: errors});
    document.body.appendChild(out);
  });
})();
</script>"""

IMAGE_MAGIC = {"image/png": b"\x89PNG\r\n\x1a\n", "image/jpeg": b"\xff\xd8\xff", "image/gif": b"GIF8"}


class Refs(html.parser.HTMLParser):
    """Collects (tag, attribute, value) of every reference a browser would load."""

    def __init__(self):
        super().__init__()
        self.refs = []
        self.styles = []
        self._in_style = False

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        for key in ("src", "href", "data", "poster"):
            if key in a and a[key] is not None and tag != "a":
                self.refs.append((tag, key, a[key]))
        if "style" in a and a["style"]:
            self.styles.append(a["style"])
        self._in_style = tag == "style"

    def handle_endtag(self, tag):
        if tag == "style":
            self._in_style = False

    def handle_data(self, data):
        if self._in_style:
            self.styles.append(data)


def static_problems(text):
    p = Refs()
    p.feed(text)
    problems = []
    for css in p.styles:
        for url in re.findall(r"url\(\s*['\"]?([^'\")]+)", css):
            if not url.startswith("data:"):
                problems.append("CSS url() to an outside file: " + url[:80])
    for tag, key, value in p.refs:
        if value.startswith("#"):
            continue
        if not value.startswith("data:"):
            problems.append("<%s %s=%s> is not embedded (not a data: URI)" % (tag, key, value[:80]))
            continue
        m = re.match(r"data:([^;,]+)(;base64)?,(.*)", value, re.S)
        if not m:
            problems.append("<%s %s> has a malformed data URI" % (tag, key))
            continue
        if tag != "img":
            continue
        mime, is_b64, payload = m.groups()
        try:
            raw = base64.b64decode(payload, validate=True) if is_b64 else payload.encode()
        except ValueError as e:
            problems.append("<img> data does not decode: %s" % e)
            continue
        magic = IMAGE_MAGIC.get(mime)
        if magic is not None and not raw.startswith(magic):
            problems.append("<img> data is not a %s (%d bytes)" % (mime, len(raw)))
        elif magic is None and mime != "image/svg+xml":
            problems.append("<img> of type %s" % mime)
    return problems


def find_chromium(given):
    for c in ([given] if given else []) + ["chromium", "chromium-browser", "google-chrome"]:
        path = shutil.which(c) if c else None
        if path:
            return path
    return None


def render(chromium, page_text):
    head = re.search(r"<head[^>]*>", page_text, re.I)
    if not head:
        return None, "", ["the page has no <head>"]
    probed = page_text[: head.end()] + PROBE + page_text[head.end():]
    with tempfile.TemporaryDirectory(prefix="evio_report_check_") as tmp:
        path = os.path.join(tmp, "index.html")
        with open(path, "w", encoding="utf-8") as f:
            f.write(probed)
        cmd = [chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
               "--no-first-run", "--disable-extensions", "--user-data-dir=" + os.path.join(tmp, "profile"),
               "--enable-logging=stderr", "--v=0", "--virtual-time-budget=20000", "--dump-dom", "file://" + path]
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        except subprocess.TimeoutExpired:
            return None, "", ["Chromium did not finish within 120 s"]
    m = re.search(r'<pre id="evio-report-probe">(.*?)</pre>', r.stdout, re.S)
    if not m:
        return None, r.stderr, ["the probe did not report (Chromium exit code %d): the page's scripts did not run "
                                "to 'load'; stderr: %s" % (r.returncode, r.stderr.strip()[-400:])]
    return json.loads(html.unescape(m.group(1))), r.stderr, []


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("page", help="the report's index.html")
    ap.add_argument("--min-images", type=int, default=0, help="fail when the page shows fewer images")
    ap.add_argument("--chromium", help="the browser (default: chromium on PATH)")
    args = ap.parse_args()
    with open(args.page, encoding="utf-8") as f:
        text = f.read()
    problems = static_problems(text)
    chromium = find_chromium(args.chromium)
    if chromium is None:
        print("SKIPPED: Chromium is not installed (apt-get install chromium); only the static checks ran: %s" %
              ("; ".join(problems) if problems else "no problem"))
        sys.exit(1 if problems else 77)
    probe, log, errors = render(chromium, text)
    problems += errors
    if probe is not None:
        problems += ["broken image: " + b for b in probe["broken"]]
        problems += probe["errors"]
        if probe["images"] < args.min_images:
            problems.append("%d images shown, expected at least %d" % (probe["images"], args.min_images))
    for line in log.splitlines():
        if "Uncaught" in line or ("CONSOLE" in line and "error" in line.lower()):
            problems.append("console: " + line.strip()[:200])
    if problems:
        print("%s: %d problem(s):\n  %s" % (args.page, len(problems), "\n  ".join(problems)))
        sys.exit(1)
    print("%s: %d images, all decoded; no script error; self-contained (%s)" % (args.page, probe["images"], chromium))


if __name__ == "__main__":
    main()

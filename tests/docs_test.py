#!/usr/bin/env python3
"""docs_test: README.md and docs/*.md stay true to the build they describe.

Checks, against the built `imr` (and imr-synth), that in every page:
  - every relative link and image resolves from the page's own folder, inside the repository,
    and every #anchor names a heading of its target page (GitHub's slugs);
  - every `imr <command>` named in code exists, and every flag given to it is in
    `imr <command> --help` (imr mesh also takes imr run's, which it hands on); a flag named alone
    (`--force`) exists in some imr command, imr-synth, or the source of another of our tools;
  - every option named exists in `imr options`: `engine.X`, `input.options.X`, `evaluation.X`,
    `pipeline[i].params.X`, the keys of inline JSON, and every backticked snake_case name, which
    must be an option, a value an option accepts, an input format, a job key (asked of
    `imr validate`) or a name listed in NOT_OPTIONS below (report keys, file fields, code);
  - every fenced ```json block parses, and every job among them passes `imr validate` (run in a
    scratch folder where the paths it names exist as empty files and folders).

Before the pages, it checks itself on a small page with one fault of each kind and fails when any
fault goes unseen. Standard library only.

  docs_test.py --source REPO --imr build/bin/imr [--synth build/bin/imr-synth] [FILES...]
"""
import argparse
import glob
import json
import os
import re
import subprocess
import sys
import tempfile

# Backticked snake_case names in the docs that are not options: keys of report.json and other
# outputs, fields of input formats, names in code. A name here is not checked; an option renamed
# in the code stays unknown (it is not in this list), so the page that names it fails.
NOT_OPTIONS = {
    # PLY face properties (docs/interop.md: what OpenMVS reads)
    "vertex_index", "vertex_indices",
    # the SDK's structs and fields (docs/plugins.md, docs/tiles.md), glTF extras
    "imr_mesh_view", "imr_export_request", "vertex_keys", "gltf_rotation", "texel_size", "imr_upright",
    "local_transform",  # tileset.json asset.extras.imr (docs/tiles.md)
    "lod_tiles", "tiles_per_level", "pending_triangles_peak", "subtree_bytes", "tileset_writes", "tileset_bytes",  # tileset.json, report.json tiles.lod
    "engine_bytes",  # report.json memory, imr run --trace records (benchmarks.md, reliability.md)
    "heap_bytes", "final_heap_bytes",  # imr run --trace records, report.json memory (reliability.md)
    "on_from_update",  # report.json engine.forget (engine.md: forget auto)
    "imr_mesh_stream", "export_mesh_stream", "recent_keyframes_begin", "keyframe_images",
    "final_call", "imr_refine_request", "imr_refine_result", "cameras_in_o", "back_facing",
    # report.json, summary.json, evaluation output
    "stage_seconds", "engine_scale", "cells_opened", "camera_regrowths", "export_input", "invariant_checks", "rays_walked_exact",
    "rays_uncast_listed", "ray_mismatches", "road_surface", "completeness_visible", "log_tail",
    "scanner_view",
    # fields of input and output formats (SLAM JSON, OpenMVG, COLMAP, KITTI, imr's stream)
    "slam_data_version", "view_priors", "prior_focal_length", "focal_length", "colmap_model",
    "colmap_params", "imr_stream", "sfm_data", "image_0", "image_2",
    # names in code, tests, the SDK and the peers
    "walk_to_next_3", "side_of_cell", "insert_in_hole", "imr_camera", "keyframe_image",
    "release_keyframe_image", "engine_property_test", "imr_track_observation",
    "imr_point_estimate", "imr_track_view", "imr_refiner_update", "struct_size", "params_schema",
    "removed_count", "is_keyframe", "docs_test", "update_points_position", "delaunay_mesher", "model_analyzer",
    "automatic_reconstructor", "feature_extractor", "exhaustive_matcher",
    # the Python module's functions, arguments and keys (docs/python.md)
    "add_keyframe", "new_ids", "new_positions", "new_cameras", "moved_ids", "moved_positions",
    "moved_cameras", "removed_ids", "point_ids", "weight_policy_params", "read_colmap",
    "read_slam_json", "read_openmvg", "set_log_level", "keyframes_held",
}

# Flags of other programs the docs name alone.
FOREIGN_FLAGS = {"--dependency", "--param",  # sbatch's, GCC's
                 "--resolution-level", "--min-resolution", "--decimate",  # OpenMVS RefineMesh's
                 "--regularity-weight"}

SNAKE = re.compile(r"^[a-z][a-z0-9]*(?:_[a-z0-9]+)+$")
FLAG_TOKEN = re.compile(r"^-{1,2}[A-Za-z][A-Za-z0-9-]*$")
EXTENSIONS = {"h", "hpp", "cc", "cpp", "c", "json", "md", "txt", "so", "py", "sh", "cjs", "png"}


class Problems:
    def __init__(self):
        self.items = []
        self.checked = {"links": 0, "imr commands": 0, "flags": 0, "option names": 0,
                        "job examples": 0}

    def add(self, where, message):
        self.items.append(f"{where}: {message}")


def run(cmd, cwd=None):
    p = subprocess.run(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                       text=True, errors="replace")
    return p.returncode, p.stdout


# ---- what the build knows ------------------------------------------------------------------

def help_flags(text):
    """Flags listed in a Boost.Program_options help: the lines after 'options:' that start with
    a dash, at most four spaces in ('  -o [ --out ] FILE', '  --work DIR')."""
    flags = set()
    listing = False
    for line in text.splitlines():
        if line.rstrip().endswith("options:") or line.strip() == "Options:":
            listing = True
            continue
        if not listing:
            continue
        m = re.match(r"^ {1,4}(-[A-Za-z0-9])?(?: \[ )?(--[A-Za-z0-9][A-Za-z0-9-]*)?", line)
        if m:
            for g in m.groups():
                if g:
                    flags.add(g)
    return flags


def imr_commands(imr):
    _, text = run([imr, "--help"])
    commands, in_list = [], False
    for line in text.splitlines():
        if line.startswith("Commands:"):
            in_list = True
            continue
        if in_list:
            if not line.startswith("  "):
                if line.strip():
                    in_list = False
                continue
            m = re.match(r"^  ([a-z]+)\b", line)
            if m:
                commands.append(m.group(1))
    if not commands:
        raise SystemExit(f"docs_test: `{imr} --help` lists no commands:\n{text}")
    flags = {}
    for c in commands:
        rc, text = run([imr, c, "--help"])
        flags[c] = help_flags(text)
        # A command of subcommands (imr tiles merge): the subcommands' flags are the command's.
        for sub in sorted(set(re.findall(rf"\bimr {c} ([a-z]+)\b", text))):
            sub_rc, sub_text = run([imr, c, sub, "--help"])
            if sub_rc == 0:
                flags[c] |= help_flags(sub_text)
        if rc != 0 or not flags[c]:
            raise SystemExit(f"docs_test: `imr {c} --help` failed or lists no options:\n{text}")
    if "mesh" in flags:  # imr mesh hands every other option to imr run
        flags["mesh"] |= flags.get("run", set())
    flags[""] = help_flags(run([imr, "--help"])[1])  # imr --version, imr --help
    return flags


def imr_options(imr):
    """{section: set(names)} from `imr options`: 'engine', 'evaluation', 'input:<format>',
    'plugin:<id>'; and the values enumerated ('one of "a", "b" or "c"')."""
    rc, text = run([imr, "options"])
    if rc != 0:
        raise SystemExit(f"docs_test: `imr options` failed:\n{text}")
    sections, values, current = {}, set(), None
    for line in text.splitlines():
        if not line.strip():
            continue
        if not line.startswith(" "):
            head = line.strip()
            if head.startswith("input format "):
                current = "input:" + head.split()[2]
            elif head.startswith("plugin "):
                current = "plugin:" + head.split()[1]
            else:
                current = head.split()[0]
            sections[current] = set()
            continue
        m = re.match(r"^  ([a-z][a-z0-9_]*)  ", line)
        if m and current:
            sections[current].add(m.group(1))
            # the values a string option accepts: string (one of "a", "b" or "c")
            accepts = re.search(r"one of ([^)]*)\)", line)
            if accepts:
                values |= set(re.findall(r'"([a-z0-9_]+)"', accepts.group(1)))
    if not sections.get("engine"):
        raise SystemExit(f"docs_test: `imr options` lists no engine options:\n{text}")
    return sections, values


def job_keys(imr, scratch):
    """The keys a job file accepts at each level, from `imr validate`'s 'unknown key (expected
    ...)' on a probe job."""
    probe = {"sequences": ["street"], "input": {"format": "synthetic", "__probe__": 1},
             "output": {"directory": "r/{sequence}", "__probe__": 1},
             "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp",
                           "__probe__": 1}], "__probe__": 1}
    path = os.path.join(scratch, "probe.json")
    with open(path, "w") as f:
        json.dump(probe, f)
    _, text = run([imr, "validate", path])
    keys = {}
    for m in re.finditer(r"^\s*(\S*?)\.?__probe__: unknown key \(expected ([^)]*)\)", text, re.M):
        where = m.group(1) or "job"
        where = re.sub(r"\[\d+\]", "", where)
        keys[where] = set(re.split(r", | or ", m.group(2)))
    for level in ("job", "input", "output", "pipeline"):
        if level not in keys:
            raise SystemExit(f"docs_test: `imr validate` did not name the keys of {level}:\n{text}")
    return keys


def tool_source_flags(source):
    """Flags our tools without a --help listing parse (imr-bench, imr-soak, scripts):
    string literals "--name" and shell case labels in tools/."""
    flags = set()
    for path in glob.glob(os.path.join(source, "tools", "**", "*"), recursive=True):
        if "node_modules" in path or not os.path.isfile(path):
            continue
        if not path.endswith((".cc", ".h", ".sh", ".py")):
            continue
        with open(path, encoding="utf-8", errors="replace") as f:
            text = f.read()
        flags |= set(re.findall(r'["\'](--[a-z0-9][a-z0-9-]*)', text))
        flags |= set(re.findall(r"^\s*(--[a-z0-9][a-z0-9-]*)\)", text, re.M))
    return flags


class Knowledge:
    def __init__(self, args, scratch):
        self.commands = imr_commands(args.imr)
        self.synth = help_flags(run([args.synth, "--help"])[1]) if args.synth else set()
        self.sections, self.values = imr_options(args.imr)
        self.job = job_keys(args.imr, scratch)
        self.engine = self.sections["engine"]
        self.evaluation = self.sections.get("evaluation", set())
        self.input_options = set().union(*(v for k, v in self.sections.items()
                                           if k.startswith("input:")))
        self.params = set().union(*(v for k, v in self.sections.items()
                                    if k.startswith("plugin:")))
        self.formats = {k.split(":", 1)[1] for k in self.sections if k.startswith("input:")}
        self.all_options = set().union(*self.sections.values())
        self.all_job_keys = set().union(*self.job.values())
        # plugin ids' last parts name them in prose (`weighted_mean`: org.imr.policy.weighted_mean)
        self.plugin_names = {k.rsplit(".", 1)[-1] for k in self.sections if k.startswith("plugin:")}
        self.names = (self.all_options | self.values | self.formats | self.all_job_keys |
                      self.plugin_names | {"weight_policy", "features", "refiner", "mesh_refiner", "exporter"})
        self.all_flags = set().union(*self.commands.values()) | self.synth
        self.tool_flags = tool_source_flags(args.source)
        self.imr = args.imr


# ---- reading a page ------------------------------------------------------------------------

def split_page(text):
    """(prose lines with line numbers, fenced blocks as (lang, first line number, lines))."""
    prose, blocks, fence = [], [], None
    for n, line in enumerate(text.split("\n"), 1):
        m = re.match(r"^\s*(```+)(\S*)", line)
        if fence is None and m:
            fence = (m.group(1), m.group(2).lower(), n + 1, [])
            continue
        if fence is not None and re.match(r"^\s*" + fence[0] + r"\s*$", line):
            blocks.append((fence[1], fence[2], fence[3]))
            fence = None
            continue
        if fence is not None:
            fence[3].append(line)
        else:
            prose.append((n, line))
    return prose, blocks


def code_spans(prose):
    """Inline code spans with their line numbers (a span may run over a line end)."""
    spans = []
    text = "\n".join(line for _, line in prose)
    starts = [n for n, _ in prose]
    offsets, pos = [], 0
    for _, line in prose:
        offsets.append(pos)
        pos += len(line) + 1
    for m in re.finditer(r"(`+)(.+?)\1", text, re.S):
        line_index = max(i for i, o in enumerate(offsets) if o <= m.start())
        spans.append((starts[line_index], m.group(2).replace("\n", " ").strip()))
    return spans


def slug(heading):
    h = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip())
    h = h.lower()
    h = re.sub(r"[^\w\- ]", "", h)
    return h.replace(" ", "-")


def anchors(path):
    with open(path, encoding="utf-8") as f:
        prose, _ = split_page(f.read())
    seen, result = {}, set()
    for _, line in prose:
        m = re.match(r"^#{1,6}\s+(.*?)\s*#*\s*$", line)
        if not m:
            continue
        s = slug(m.group(1))
        k = seen.get(s, 0)
        result.add(s if k == 0 else f"{s}-{k}")
        seen[s] = k + 1
    return result


# ---- the checks ----------------------------------------------------------------------------

def check_links(page, prose, source, problems):
    folder = os.path.dirname(page)
    root = os.path.realpath(source)
    text_lines = [(n, re.sub(r"`[^`]*`", "", line)) for n, line in prose]
    for n, line in text_lines:
        for m in re.finditer(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)", line):
            target = m.group(1)
            if re.match(r"^[a-z][a-z0-9+.-]*:", target):  # http:, https:, mailto:
                continue
            problems.checked["links"] += 1
            path, _, anchor = target.partition("#")
            resolved = os.path.realpath(os.path.join(folder, path)) if path else page
            where = f"{os.path.relpath(page, source)}:{n}"
            if not (resolved == root or resolved.startswith(root + os.sep)):
                problems.add(where, f"link {target} leaves the repository")
                continue
            if not os.path.exists(resolved):
                problems.add(where, f"link {target}: {os.path.relpath(resolved, source)} does not exist")
                continue
            if anchor:
                if not resolved.endswith(".md") or os.path.isdir(resolved):
                    problems.add(where, f"link {target}: an anchor into a file that is not Markdown")
                elif anchor not in anchors(resolved):
                    problems.add(where, f"link {target}: no heading of {os.path.relpath(resolved, source)} "
                                        f"has the anchor #{anchor}")


def command_chunks(prose_spans, blocks):
    """Texts that may hold command lines: inline spans, and the logical lines of fenced shell
    blocks (backslash continuations joined). In a synopsis, an indented line of options
    ('    [--jobs J] [--force]') continues the command of the line above: it is checked as
    '<that command> <its options>'."""
    chunks = list(prose_spans)
    head = re.compile(r"^\s*(?:[\w.~${}-]*/)*imr(?:-synth)?(?:\s+[a-z]+)?")
    for lang, first, lines in blocks:
        if lang not in ("", "sh", "bash", "shell", "console", "text"):
            continue
        current, start, prefix = "", first, ""
        for i, line in enumerate(lines):
            stripped = line.rstrip()
            if current.endswith("\\"):
                current = current[:-1] + " " + stripped.strip()
                continue
            if current:
                chunks.append((start, current))
                current = ""
            if prefix and re.match(r"^\s+\[?-", stripped):
                chunks.append((first + i, prefix + " " + stripped.strip()))
                continue
            if prefix and re.match(r"^\s", stripped):
                continue  # a synopsis's description, under its command
            m = head.match(stripped)
            prefix = m.group(0).strip() if m else ""
            current, start = stripped, first + i
        if current:
            chunks.append((start, current))
    return chunks


def strip_comment(text):
    out, quote = [], None
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (i == 0 or text[i - 1].isspace()):
            break
        out.append(ch)
    return "".join(out)


def flag_tokens(words):
    for w in words:
        for part in re.split(r"[\[\]|]", w):
            part = part.split("=", 1)[0].rstrip(".,;:)")
            if FLAG_TOKEN.match(part):
                yield part


def check_commands(page_rel, chunks, know, problems):
    invocation = re.compile(r"(?:(?<=^)|(?<=[\s;&|(`$]))(?:[\w.~${}-]*/)*(imr|imr-synth)(?=\s|$)")
    for n, chunk in chunks:
        text = strip_comment(chunk)
        hits = list(invocation.finditer(text))
        for i, m in enumerate(hits):
            end = hits[i + 1].start() if i + 1 < len(hits) else len(text)
            tail = re.split(r"&&|\|\||;|\|(?!\s*-)", text[m.end():end])[0]
            words = tail.split()
            where = f"{page_rel}:{n}"
            if m.group(1) == "imr-synth":
                for flag in flag_tokens(words):
                    problems.checked["flags"] += 1
                    if flag not in know.synth:
                        problems.add(where, f"imr-synth has no option {flag} (imr-synth --help)")
                continue
            if not words:
                continue
            command = words[0]
            if command.startswith("-"):
                command, args = "", words
            elif re.match(r"^[a-z]+$", command):
                args = words[1:]
            else:
                continue  # `imr` followed by something else: a path, a placeholder
            if command not in know.commands:
                problems.add(where, f"imr has no command '{command}' (imr --help)")
                continue
            problems.checked["imr commands"] += 1
            for flag in flag_tokens(args):
                problems.checked["flags"] += 1
                if flag not in know.commands[command]:
                    name = f"imr {command}".strip()
                    problems.add(where, f"`{name}` has no option {flag} ({name} --help)")


def check_lone_flags(page_rel, spans, know, problems):
    for n, span in spans:
        words = span.split()
        if not words or not FLAG_TOKEN.match(words[0].split("=", 1)[0]):
            continue
        flag = words[0].split("=", 1)[0]
        if not flag.startswith("--"):
            continue
        problems.checked["flags"] += 1
        if flag in know.all_flags or flag in know.tool_flags or flag in FOREIGN_FLAGS:
            continue
        problems.add(f"{page_rel}:{n}", f"the option {flag} exists in no imr command, in imr-synth "
                                        "or in our tools' sources")


def check_dotted(page_rel, n, text, know, problems):
    sets = {"engine": know.engine, "input.options": know.input_options,
            "evaluation": know.evaluation, "output": know.job.get("output", set())}
    for m in re.finditer(r"(?<![\w/.\[])(engine|input\.options|evaluation|output)\.([a-z_][a-z0-9_]*)(?![\w.(])", text):
        prefix, name = m.group(1), m.group(2)
        if name in EXTENSIONS:
            continue
        problems.checked["option names"] += 1
        if name not in sets[prefix]:
            problems.add(f"{page_rel}:{n}", f"{prefix}.{name}: no such option in `imr options`"
                                            f" / the job's keys")
    for m in re.finditer(r"pipeline\[\d+\]\.params\.([a-z_][a-z0-9_]*)", text):
        problems.checked["option names"] += 1
        if m.group(1) not in know.params:
            problems.add(f"{page_rel}:{n}", f"{m.group(0)}: no plugin has the param {m.group(1)}")


def check_json_keys(where, value, context, know, problems):
    level_sets = {"engine": know.engine, "options": know.input_options, "params": know.params,
                  "evaluation": know.evaluation, "input": know.job["input"],
                  "output": know.job["output"], "stage": know.job["pipeline"], "job": know.job["job"]}
    if isinstance(value, list):
        for v in value:
            check_json_keys(where, v, "stage" if context == "pipeline" else context, know, problems)
        return
    if not isinstance(value, dict):
        return
    allowed = level_sets.get(context)
    for key, v in value.items():
        problems.checked["option names"] += 1
        if allowed is not None and key not in allowed:
            problems.add(where, f'"{key}" is not a key of {context} (imr options; imr validate)')
        elif allowed is None and key not in know.names:
            problems.add(where, f'"{key}" is neither an option nor a job key')
        child = key if key in ("engine", "options", "params", "evaluation", "input", "output",
                               "pipeline") else "leaf"
        if child != "leaf":
            check_json_keys(where, v, child, know, problems)


def check_options(page_rel, spans, blocks, know, problems):
    for n, span in spans:
        check_dotted(page_rel, n, span, know, problems)
        if SNAKE.match(span) and span not in NOT_OPTIONS:
            problems.checked["option names"] += 1
        if SNAKE.match(span) and span not in know.names and span not in NOT_OPTIONS:
            problems.add(f"{page_rel}:{n}", f"`{span}` is not an option, a value or a job key "
                                            "`imr options` and `imr validate` know (a report key, "
                                            "a file's field or a name in code? add it to "
                                            "NOT_OPTIONS in tests/docs_test.py)")
        if "{" in span and '"' in span:
            for candidate in (span, "{" + span + "}"):
                try:
                    value = json.loads(candidate)
                except ValueError:
                    continue
                context = "job" if candidate == span and isinstance(value, dict) and (
                    "sequences" in value or "pipeline" in value) else None
                check_json_keys(f"{page_rel}:{n}", value, context, know, problems)
                break
    for lang, first, lines in blocks:
        if lang in ("", "sh", "bash", "shell", "console", "text"):
            for i, line in enumerate(lines):
                check_dotted(page_rel, first + i, line, know, problems)


def placeholders(job, job_dir, scratch, where, problems):
    """Make the files and folders a job names (sequences, plugin_paths, evaluation.truth) exist
    under the scratch folder, empty: imr validate checks that they exist, not what they hold."""
    def make(path, as_dir):
        if os.path.isabs(path):
            problems.add(where, f"job example names an absolute path ({path}); use a relative one")
            return
        full = os.path.realpath(os.path.join(job_dir, path.replace("*", "x").replace("?", "x")))
        if not full.startswith(os.path.realpath(scratch) + os.sep):
            problems.add(where, f"job example path {path} climbs out of any folder")
            return
        if as_dir or not os.path.splitext(full)[1]:
            os.makedirs(full, exist_ok=True)
        else:
            os.makedirs(os.path.dirname(full), exist_ok=True)
            open(full, "a").close()

    fmt = (job.get("input") or {}).get("format")
    if fmt != "synthetic":
        for s in job.get("sequences", []):
            if isinstance(s, str):
                make(s, s.endswith("/"))
    for p in job.get("plugin_paths", []):
        if isinstance(p, str):
            make(p, True)
    truth = (job.get("evaluation") or {}).get("truth")
    if isinstance(truth, str) and truth not in ("", "velodyne") and "." in truth:
        make(truth, False)


def check_json_blocks(page_rel, blocks, know, scratch, problems):
    for index, (lang, first, lines) in enumerate(blocks):
        if lang != "json":
            continue
        where = f"{page_rel}:{first}"
        try:
            value = json.loads("\n".join(lines))
        except ValueError as e:
            problems.add(where, f"```json block does not parse: {e}")
            continue
        if not (isinstance(value, dict) and ("sequences" in value or "pipeline" in value)):
            check_json_keys(where, value, None, know, problems)
            continue
        # A job: validate it where the paths it names exist (three folders deep, so that "../.."
        # stays inside the scratch folder).
        root = os.path.join(scratch, f"job{len(os.listdir(scratch))}")
        job_dir = os.path.join(root, "a", "b", "c")
        os.makedirs(job_dir)
        placeholders(value, job_dir, root, where, problems)
        path = os.path.join(job_dir, "job.json")
        with open(path, "w", encoding="utf-8") as f:
            f.write("\n".join(lines))
        problems.checked["job examples"] += 1
        rc, out = run([know.imr, "validate", path], cwd=job_dir)
        if rc != 0:
            problems.add(where, "job example fails `imr validate`:\n    " +
                         "\n    ".join(out.strip().splitlines()))


def check_page(path, source, know, scratch, problems):
    with open(path, encoding="utf-8") as f:
        text = f.read()
    page_rel = os.path.relpath(path, source)
    prose, blocks = split_page(text)
    spans = code_spans(prose)
    check_links(path, prose, source, problems)
    check_commands(page_rel, command_chunks(spans, blocks), know, problems)
    check_lone_flags(page_rel, spans, know, problems)
    check_options(page_rel, spans, blocks, know, problems)
    check_json_blocks(page_rel, blocks, know, scratch, problems)


SELF_TEST_PAGE = """# A page with one fault of each kind

## Real heading

[fine](#real-heading) [broken link](no-such-file.md) [broken anchor](#no-such-heading)

`imr run job.json --no-such-flag` and `imr frobnicate x` and `imr-synth --no-such-synth-flag`;
`--no-such-flag-anywhere` alone.

Set `engine.no_such_engine_option` or `no_such_option_name`; `{"engine": {"no_such_key": 1}}`.

```json
{"sequences": ["street"], "input": {"format": "synthetic"},
 "engine": {"window": 0},
 "pipeline": [{"kind": "exporter", "plugin": "org.imr.exporter.assimp"}],
 "output": {"directory": "runs/{sequence}"}}
```

```json
{"not json
```
"""
SELF_TEST_EXPECTED = ["no-such-file.md", "#no-such-heading", "option --no-such-flag (",
                      "'frobnicate'", "--no-such-synth-flag", "--no-such-flag-anywhere",
                      "engine.no_such_engine_option", "`no_such_option_name`", '"no_such_key"',
                      "fails `imr validate`", "does not parse"]


def self_test(source, know, scratch):
    folder = tempfile.mkdtemp(dir=scratch)
    page = os.path.join(folder, "page.md")
    with open(page, "w") as f:
        f.write(SELF_TEST_PAGE)
    problems = Problems()
    check_page(page, folder, know, tempfile.mkdtemp(dir=scratch), problems)
    report = "\n".join(problems.items)
    missed = [e for e in SELF_TEST_EXPECTED if e not in report]
    if missed or len(problems.items) != len(SELF_TEST_EXPECTED):
        print("docs_test: the self-test page's faults were not all found exactly once; missed: "
              f"{missed}\nfound:\n{report}", file=sys.stderr)
        return False
    return True


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--source", required=True, help="the repository's root")
    ap.add_argument("--imr", required=True, help="the built imr")
    ap.add_argument("--synth", help="the built imr-synth")
    ap.add_argument("files", nargs="*", help="pages (default: README.md and docs/*.md)")
    args = ap.parse_args()
    args.imr = os.path.realpath(args.imr)
    args.synth = os.path.realpath(args.synth) if args.synth else None
    source = os.path.realpath(args.source)
    pages = args.files or [os.path.join(source, "README.md")] + sorted(
        glob.glob(os.path.join(source, "docs", "*.md")))
    with tempfile.TemporaryDirectory(prefix="imr-docs-test-") as scratch:
        know = Knowledge(args, scratch)
        if not self_test(source, know, scratch):
            return 1
        problems = Problems()
        for page in pages:
            check_page(os.path.realpath(page), source, know, scratch, problems)
    for p in problems.items:
        print(p)
    if problems.items:
        print(f"docs_test: {len(problems.items)} problem(s) in {len(pages)} page(s): the docs "
              "name links, commands, options or jobs the build does not have")
        return 1
    counts = ", ".join(f"{v} {k}" for k, v in problems.checked.items())
    print(f"docs_test: {len(pages)} pages, all true: {counts} checked")
    return 0


if __name__ == "__main__":
    sys.exit(main())

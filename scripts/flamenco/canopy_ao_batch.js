// Flamenco job type "Canopy AO Batch": bakes Canopy AO into many .blend files, one Flamenco
// task per group of files, each running the same Blender command line as the batch command's
// local and Slurm back ends (addon/canopy_ao/batch/plan.py, task_command); the tests compare
// the two argument for argument (tests/python/test_batch.py).
//
// Install: copy this file into the Flamenco Manager's scripts/ folder and restart it; the
// workers need the canopy_ao add-on installed (scripts/install_addon.sh) and shared storage for
// the files and the output folder. Each task writes the baked copies and one JSON report per
// file; a file already up to date is skipped, so a task Flamenco retries redoes only what
// failed. For summary.csv, run `python3 -m canopy_ao.batch` with the same files, --output and
// bake options afterwards: every file is then up to date and only the summary is written.

const JOB_TYPE = {
    label: "Canopy AO Batch",
    description: "Bake Canopy AO into many .blend files",
    settings: [
        // One absolute path per line, as the workers see them.
        { key: "files", type: "string", required: true, editable: true,
          description: "The .blend files to bake, one absolute path per line" },
        { key: "output", type: "string", subtype: "dir_path", required: true, editable: true,
          description: "Folder for the baked copies, their JSON reports and summary.csv" },
        { key: "root", type: "string", subtype: "dir_path", required: false, editable: true,
          description: "Folder whose layout the outputs mirror (default: the files' common folder)" },
        { key: "bake_args", type: "string", required: false, editable: true, default: "--method auto",
          description: "Options of the bake command line (canopy_ao.cli), as typed in a shell" },
        { key: "threads", type: "int32", default: 0, editable: true,
          description: "Native-core threads per bake (0 = every core)" },
        { key: "files_per_task", type: "int32", default: 1, editable: true,
          description: "Files per Blender process (Blender's start-up is paid once per task)" },
        { key: "in_place", type: "bool", default: false, editable: true,
          description: "Save the bake into the source files themselves" },
    ],
};

// Kept identical to plan.py's WORKER_EXPR and BLENDER_ARGS (the tests check it).
const WORKER_EXPR = "import canopy_ao.batch.worker as w; w.main()";
// --python-exit-code 1: a worker without the add-on fails the task instead of exiting 0.
const BLENDER_ARGS = ["-b", "--factory-startup", "--addons", "canopy_ao", "--python-exit-code", "1"];

function compileJob(job) {
    const settings = job.settings;
    const files = parseFiles(settings.files);
    if (files.length == 0) {
        throw "Canopy AO Batch: no .blend files given";
    }
    const perTask = settings.files_per_task || 1;
    if (perTask < 1) {
        throw "Canopy AO Batch: files_per_task must be >= 1";
    }
    const root = settings.root || commonRoot(files);
    const bakeArgs = splitWords(settings.bake_args || "");
    for (let i = 0; i * perTask < files.length; i++) {
        const chunk = files.slice(i * perTask, (i + 1) * perTask);
        const task = author.Task(`bake-${i}`, "blender");
        task.addCommand(author.Command("blender-render", {
            exe: "{blender}",
            exeArgs: "",
            argsBefore: BLENDER_ARGS,
            blendfile: chunk[0],
            args: ["--python-expr", WORKER_EXPR, "--"]
                .concat(workerArgs(root, settings))
                .concat(["--files"], chunk, ["--"], bakeArgs),
        }));
        job.addTask(task);
    }
}

function workerArgs(root, settings) {
    const args = ["--root", root, "--output", settings.output];
    if (settings.threads) {
        args.push("--threads", String(settings.threads));
    }
    if (settings.in_place) {
        args.push("--in-place");
    }
    return args;
}

function parseFiles(text) {
    return String(text || "").split("\n").map((s) => s.trim()).filter((s) => s.length > 0);
}

// The deepest folder holding every file (os.path.commonpath of their folders; POSIX paths).
function commonRoot(files) {
    const dirs = files.map((f) => f.split("/").slice(0, -1));
    let common = dirs[0];
    for (const d of dirs.slice(1)) {
        let n = 0;
        while (n < common.length && n < d.length && common[n] == d[n]) n++;
        common = common.slice(0, n);
    }
    return common.join("/") || "/";
}

// Shell-like words: whitespace separates, '...' and "..." quote, backslash escapes (outside
// single quotes) - the subset of POSIX quoting Python's shlex.split agrees with.
function splitWords(text) {
    const words = [];
    let word = null;
    let quote = null;
    for (let i = 0; i < text.length; i++) {
        const c = text[i];
        if (quote) {
            if (c == quote) quote = null;
            else if (c == "\\" && quote == '"' && (text[i + 1] == '"' || text[i + 1] == "\\")) word += text[++i];
            else word += c;
        } else if (c == "'" || c == '"') {
            quote = c;
            word = word || "";
        } else if (c == "\\" && i + 1 < text.length) {
            word = (word || "") + text[++i];
        } else if (/\s/.test(c)) {
            if (word !== null) words.push(word);
            word = null;
        } else {
            word = (word || "") + c;
        }
    }
    if (quote) {
        throw "Canopy AO Batch: unbalanced quote in bake_args";
    }
    if (word !== null) words.push(word);
    return words;
}

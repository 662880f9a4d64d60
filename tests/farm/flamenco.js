// A stand-in for the Flamenco Manager's job compiler and the Worker's `blender-render`
// command, so that Madder's job type (addon/farm/madder_bake.js) can be compiled and its
// command lines checked with node. Flamenco itself cannot be installed here. It follows
// the shape of Flamenco 3's sources (internal/manager/job_compilers, internal/worker):
//
// - the script runs in a fresh global scope that holds `author` (Task(name, type),
//   Command(name, parameters, totalStepCount)), `path`, `print`, `alert`, `frameChunker`,
//   `frameCount`, `formatTimestampLocal`; `JOB_TYPE` and `compileJob(job)` are its globals;
// - Go fields are seen from JavaScript with a lower-case first letter: job.settings,
//   job.addTask(task), task.addCommand(cmd), task.addDependency(task), task.name, …;
// - author.Task refuses an empty name or type; a frame range is "1-10,20" (or "1..10"),
//   chunks are at most chunk_size frames, merged back as "A-B", "A,B" or "A";
// - the worker runs `exe` + shell-split `exeArgs` + `argsBefore` + `blendfile` + `args`,
//   after the Manager has replaced the `{variables}` in them.

"use strict";

const fs = require("node:fs");
const posix = require("node:path").posix;
const vm = require("node:vm");

function explodeFrames(range) {
    const text = String(range).trim().replaceAll("..", "-");
    if (text === "") {
        throw new Error(`invalid range "${range}": empty range`);
    }
    const frames = new Set();
    for (const part of text.split(",")) {
        const ends = part.split("-").map((s) => s.trim());
        if (ends.length > 2 || ends.some((s) => !/^[0-9]+$/.test(s))) {
            throw new Error(`invalid range "${range}": ${part}`);
        }
        const [a, b] = [Number(ends[0]), Number(ends[ends.length - 1])];
        for (let f = a; f <= b; f++) {
            frames.add(f);
        }
    }
    return [...frames].sort((x, y) => x - y);
}

function mergeFrames(frames) {
    const out = [];
    let start = frames[0];
    for (let i = 1; i <= frames.length; i++) {
        if (i === frames.length || frames[i] !== frames[i - 1] + 1) {
            const end = frames[i - 1];
            if (end === start) out.push(`${start}`);
            else if (end === start + 1) out.push(`${start}`, `${end}`);
            else out.push(`${start}-${end}`);
            start = frames[i];
        }
    }
    return out.join(",");
}

function frameChunker(range, chunkSize) {
    if (!(chunkSize >= 1)) {
        throw new Error(`invalid chunk size, must be positive number: ${chunkSize}`);
    }
    const frames = explodeFrames(range);
    const chunks = [];
    for (let i = 0; i < frames.length; i += chunkSize) {
        chunks.push(mergeFrames(frames.slice(i, i + chunkSize)));
    }
    return chunks;
}

let taskIds = 0;

const author = {
    Task(name, type) {
        name = String(name).trim();
        type = String(type).trim();
        if (!name) throw new Error("author.Task(name, type): name is required");
        if (!type) throw new Error("author.Task(name, type): type is required");
        taskIds += 1;
        return {
            uuid: `task-${taskIds}`,
            name,
            type,
            priority: 50,
            commands: [],
            dependencies: [],
            addCommand(cmd) {
                this.commands.push(cmd);
            },
            addDependency(task) {
                this.dependencies.push(task);
            },
        };
    },
    Command(name, parameters, totalStepCount) {
        return { name, parameters, totalStepCount: totalStepCount || 0 };
    },
};

/** Loads a job compiler script the way the Manager does; returns its JOB_TYPE and a
 * `compile(settings)` that returns the authored job (its tasks in order). */
function loadJobType(file) {
    const context = vm.createContext({
        author,
        path: { basename: posix.basename, dirname: posix.dirname, join: posix.join },
        print: () => {},
        alert: () => {},
        frameChunker,
        frameCount: (range) => explodeFrames(range).length,
        formatTimestampLocal: (t) => new Date(t).toISOString().slice(0, 19).replace("T", "_").replaceAll(":", ""),
    });
    vm.runInContext(fs.readFileSync(file, "utf8"), context, { filename: file });
    const jobType = vm.runInContext("JOB_TYPE", context);
    const compileJob = vm.runInContext("compileJob", context);
    return {
        jobType,
        compile(settings, name = "job") {
            const job = {
                name,
                created: new Date(0),
                settings: { ...settings },
                tasks: [],
                addTask(task) {
                    this.tasks.push(task);
                },
            };
            compileJob(job);
            return job;
        },
    };
}

/** The Manager's defaults for settings the submitter leaves out (what Flamenco's add-on
 * sends for settings with a `default`). */
function withDefaults(jobType, settings) {
    const out = { ...settings };
    for (const s of jobType.settings) {
        if (!(s.key in out) && "default" in s) out[s.key] = s.default;
    }
    return out;
}

/** Minimal POSIX shell word splitting (quotes and backslashes), as the worker applies to
 * `exeArgs`. */
function shellSplit(text) {
    const words = [];
    let word = null;
    let quote = null;
    for (let i = 0; i < text.length; i++) {
        const c = text[i];
        if (quote) {
            if (c === quote) quote = null;
            else if (c === "\\" && quote === '"' && i + 1 < text.length) word += text[++i];
            else word += c;
        } else if (c === "'" || c === '"') {
            quote = c;
            word = word ?? "";
        } else if (c === "\\" && i + 1 < text.length) {
            word = (word ?? "") + text[++i];
        } else if (/\s/.test(c)) {
            if (word !== null) words.push(word);
            word = null;
        } else {
            word = (word ?? "") + c;
        }
    }
    if (quote) throw new Error(`unterminated quote in ${text}`);
    if (word !== null) words.push(word);
    return words;
}

/** The argv a worker runs for a `blender-render` command, with the Manager's variables
 * (e.g. {blender: "blender", blenderArgs: "-b -y"}) replaced. */
function workerArgv(command, variables) {
    if (command.name !== "blender-render") throw new Error(`not a blender-render command: ${command.name}`);
    const expand = (s) => String(s).replace(/\{([^}]+)\}/g, (m, v) => (v in variables ? variables[v] : m));
    const p = command.parameters;
    const argv = [expand(p.exe), ...shellSplit(expand(p.exeArgs || "")), ...p.argsBefore.map(expand)];
    if (p.blendfile) argv.push(expand(p.blendfile));
    return argv.concat(p.args.map(expand));
}

module.exports = { loadJobType, withDefaults, workerArgv, shellSplit, frameChunker };

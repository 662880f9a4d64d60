// Madder's Flamenco job type (addon/farm/madder_bake.js), compiled with the job-author API
// of tests/farm/flamenco.js: one bake task per object with its exact command line, render
// tasks depending on every bake, frame chunks, and clear errors for bad settings.
// Run: node --test tests/farm/

"use strict";

const assert = require("node:assert/strict");
const path = require("node:path");
const test = require("node:test");
const { loadJobType, withDefaults, workerArgv, shellSplit, frameChunker } = require("./flamenco.js");

const JOB_FILE = path.join(__dirname, "..", "..", "addon", "farm", "madder_bake.js");
const { jobType, compile } = loadJobType(JOB_FILE);

const SETTINGS = withDefaults(jobType, {
    frames: "1-10",
    chunk_size: 4,
    render_output_root: "/shared/render",
    render_output_path: "/shared/render/stains/######",
    objects: JSON.stringify(["Tablecloth", "Napkin, folded"]),
    blendfile: "/shared/jobs/stains/table.blend",
    format: "PNG",
    scene: "Scene",
});
// A farm whose Manager starts Blender with --factory-startup (extensions all disabled).
const VARIABLES = { blender: "/opt/blender/blender", blenderArgs: "-b -y --factory-startup" };

function pythonExpr(argv) {
    const i = argv.indexOf("--python-expr");
    assert.ok(i > 0, `no --python-expr in ${argv}`);
    return argv[i + 1];
}

test("the job type declares Flamenco settings, the object list evaluated in Blender", () => {
    assert.equal(typeof jobType.label, "string");
    const keys = jobType.settings.map((s) => s.key);
    for (const k of ["frames", "chunk_size", "objects", "blendfile", "format", "render_output_path"]) {
        assert.ok(keys.includes(k), `setting ${k} missing`);
    }
    for (const s of jobType.settings) {
        assert.ok(["string", "int32", "float", "bool"].includes(s.type), `${s.key}: type ${s.type}`);
    }
    const objects = jobType.settings.find((s) => s.key === "objects");
    assert.match(objects.eval, /madder/);
    assert.equal(objects.visible, "web"); // evaluated at every submission, never stale
});

test("one bake task per object, with the exact command line a worker runs", () => {
    const job = compile(SETTINGS);
    const bakes = job.tasks.filter((t) => t.name.startsWith("bake-"));
    assert.deepEqual(bakes.map((t) => t.name), ["bake-Tablecloth", "bake-Napkin, folded"]);
    for (const [task, name] of [[bakes[0], "Tablecloth"], [bakes[1], "Napkin, folded"]]) {
        assert.equal(task.type, "blender");
        assert.equal(task.commands.length, 1);
        const argv = workerArgv(task.commands[0], VARIABLES);
        assert.deepEqual(argv, [
            "/opt/blender/blender", "-b", "-y", "--factory-startup",
            "/shared/jobs/stains/table.blend",
            "--scene", "Scene",
            "--python-exit-code", "1", "--python-expr", pythonExpr(argv),
            "--command", "madder", "bake", "--object", name,
        ]);
    }
    // the bakes save the same .blend: one after the other
    assert.deepEqual(bakes[0].dependencies, []);
    assert.deepEqual(bakes[1].dependencies, [bakes[0]]);
});

test("the extension is enabled by Python before the command, whatever blenderArgs says", () => {
    const job = compile(SETTINGS);
    for (const task of job.tasks) {
        const argv = workerArgv(task.commands[0], VARIABLES);
        const expr = pythonExpr(argv);
        assert.match(expr, /addon_utils\.enable\(/);
        // an exception in it fails the task instead of rendering frames without the stain
        assert.ok(argv.indexOf("--python-exit-code") < argv.indexOf("--python-expr"));
        assert.equal(argv[argv.indexOf("--python-exit-code") + 1], "1");
        const command = argv.indexOf("--command");
        if (command >= 0) assert.ok(argv.indexOf("--python-expr") < command);
    }
});

test("render tasks cover the frames in chunks and depend on every bake", () => {
    const job = compile(SETTINGS);
    const bakes = job.tasks.filter((t) => t.name.startsWith("bake-"));
    const renders = job.tasks.filter((t) => t.name.startsWith("render-"));
    assert.equal(job.tasks.length, bakes.length + renders.length);
    assert.deepEqual(renders.map((t) => t.name), ["render-1-4", "render-5-8", "render-9,10"]);
    const frames = [];
    for (const task of renders) {
        assert.equal(task.type, "blender");
        assert.deepEqual(task.dependencies, bakes);
        const cmd = task.commands[0];
        const argv = workerArgv(cmd, VARIABLES);
        assert.deepEqual(argv.slice(0, 5), ["/opt/blender/blender", "-b", "-y", "--factory-startup", SETTINGS.blendfile]);
        const tail = argv.slice(argv.indexOf("--render-output"));
        const chunk = task.name.slice("render-".length);
        assert.deepEqual(tail, [
            "--render-output", "/shared/render/stains/######",
            "--render-format", "PNG",
            "--render-frame", chunk.replaceAll("-", ".."),
        ]);
        assert.equal(cmd.totalStepCount, chunk.includes(",") ? chunk.split(",").length : 4);
        for (const part of chunk.split(",")) {
            const [a, b] = part.split("-").map(Number);
            for (let f = a; f <= (b || a); f++) frames.push(f);
        }
    }
    assert.deepEqual(frames, [1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
    // all bakes come before any render in the task list too
    assert.ok(job.tasks.indexOf(bakes[1]) < job.tasks.indexOf(renders[0]));
});

test("frame lists and single-frame chunks", () => {
    const job = compile({ ...SETTINGS, frames: "1-3,7", chunk_size: 1 });
    const renders = job.tasks.filter((t) => t.name.startsWith("render-"));
    assert.deepEqual(renders.map((t) => t.name), ["render-1", "render-2", "render-3", "render-7"]);
    const big = compile({ ...SETTINGS, frames: "1..5,9", chunk_size: 10 });
    const only = big.tasks.filter((t) => t.name.startsWith("render-"));
    assert.equal(only.length, 1);
    assert.deepEqual(workerArgv(only[0].commands[0], VARIABLES).slice(-2), ["--render-frame", "1..5,9"]);
    assert.equal(only[0].commands[0].totalStepCount, 6);
});

test("without a scene setting the .blend's active scene is used", () => {
    const job = compile({ ...SETTINGS, scene: "" });
    for (const task of job.tasks) {
        assert.ok(!workerArgv(task.commands[0], VARIABLES).includes("--scene"));
    }
});

test("bad settings are refused with the setting named", () => {
    const cases = [
        [{ objects: "[]" }, /no object has Madder Stain enabled/],
        [{ objects: "" }, /'objects' must be a JSON list/],
        [{ objects: "Flag" }, /'objects' must be a JSON list/],
        [{ objects: '{"a": 1}' }, /'objects' must be a JSON list/],
        [{ objects: '["Flag", ""]' }, /'objects' must be a JSON list/],
        [{ objects: '["Flag", 3]' }, /'objects' must be a JSON list/],
        [{ objects: '["Flag", "Flag"]' }, /'objects' names 'Flag' twice/],
        [{ frames: "one-ten" }, /'frames' is not a frame range/],
        [{ frames: "" }, /'frames' is not a frame range/],
        [{ chunk_size: 0 }, /'chunk_size' must be a whole number/],
        [{ chunk_size: 2.5 }, /'chunk_size' must be a whole number/],
        [{ format: "FFMPEG" }, /'format' is FFMPEG, a video/],
        [{ blendfile: "" }, /'blendfile' is empty/],
        [{ render_output_path: "" }, /'render_output_path' is empty/],
    ];
    for (const [change, message] of cases) {
        assert.throws(() => compile({ ...SETTINGS, ...change }), message, JSON.stringify(change));
    }
});

test("the stand-in API behaves like Flamenco's", () => {
    assert.deepEqual(frameChunker("1-10", 4), ["1-4", "5-8", "9,10"]);
    assert.deepEqual(frameChunker("3,1..2", 5), ["1-3"]);
    assert.throws(() => frameChunker("1-5", 0), /chunk size/);
    assert.deepEqual(shellSplit(`-b -y --python-expr "a b" 'c d'`), ["-b", "-y", "--python-expr", "a b", "c d"]);
});

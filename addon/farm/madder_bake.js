// SPDX-License-Identifier: GPL-3.0-or-later
//
// Madder on Flamenco: a job type (a Flamenco "job compiler script") that bakes the stain of
// every object with Madder Stain enabled, one task per object, then renders the frames in
// chunks, each render task depending on every bake.
//
// Install: copy this file into the `scripts/` folder next to the Flamenco Manager executable
// and restart the Manager; the job type is then `madder-bake` ("Madder: Bake Stains and
// Render"). README.md, "On a render farm", has the whole setup.
//
// What a worker runs (the Manager's `{blender}` and `{blenderArgs}` variables first):
//
//   blender {blenderArgs} FILE --python-exit-code 1 --python-expr ENABLE_MADDER \
//       --command madder bake --object NAME
//   blender {blenderArgs} FILE --python-exit-code 1 --python-expr ENABLE_MADDER \
//       --render-output OUT --render-format FORMAT --render-frame A..B
//
// ENABLE_MADDER enables the Madder extension installed on the worker. Farms often start
// Blender with --factory-startup (in blenderArgs), which skips the user's preferences and so
// leaves every extension disabled, even an installed one: then neither `--command madder`
// nor the playback handler that renders the stain would exist. Enabling it by Python works
// with and without --factory-startup, and `--python-exit-code 1` turns a worker without
// Madder into a failed task that says so, instead of frames rendered without the stain.
//
// Bakes run one after another: each saves the .blend so that its object knows its cache
// (the path and the references playback normalizes by), and two Blenders saving the same
// file at once would lose one of the two updates. Each render task depends on all of them.
//
// The object list comes from the .blend at submission: Flamenco's Blender add-on evaluates
// the `objects` setting's Python expression in the submitting Blender.

const OBJECTS_EVAL =
    "__import__('json').dumps([o.name for o in C.scene.objects " +
    "if o.type == 'MESH' and getattr(getattr(o, 'madder', None), 'enabled', False)])";

// Run by Blender on the worker before the bake or the render (one Python string).
const ENABLE_MADDER = [
    "import addon_utils, bpy",
    "names = sorted(m.__name__ for m in addon_utils.modules() if m.__name__.startswith('bl_ext.') and m.__name__.endswith('.madder'))",
    "if not names:",
    "    raise RuntimeError('Madder: the Madder extension is not installed on this worker; install it with: blender --command extension install-file -r user_default -e madder-<version>.zip')",
    "if not any(n in bpy.context.preferences.addons for n in names) and addon_utils.enable(names[0], default_set=True) is None:",
    "    raise RuntimeError('Madder: the extension ' + names[0] + ' is installed but failed to enable (see the traceback above)')",
    "print('Madder: using the extension', names[0])",
].join("\n");

const JOB_TYPE = {
    label: "Madder: Bake Stains and Render",
    description: "Bake the Madder stain of each enabled object (one task each), then render the frames",
    settings: [
        // Settings for artists to determine:
        { key: "frames", type: "string", required: true,
          eval: "f'{C.scene.frame_start}-{C.scene.frame_end}'",
          evalInfo: { showLinkButton: true, description: "Scene frame range" },
          description: "Frames to render, e.g. '1-250' or '1-10,20'. The bakes always cover the scene's frame range" },
        { key: "chunk_size", type: "int32", default: 1, propargs: { min: 1 }, visible: "submission",
          description: "Number of frames rendered by one render task" },
        { key: "render_output_root", type: "string", subtype: "dir_path", required: true, visible: "submission",
          description: "Shared folder that receives the rendered frames, in a sub-folder named after the job" },
        { key: "render_output_path", type: "string", subtype: "file_path", editable: false,
          eval: "str(Path(abspath(settings.render_output_root), jobname, '######'))",
          description: "Where the frames are written" },

        // Automatically evaluated at submission:
        { key: "objects", type: "string", required: true, eval: OBJECTS_EVAL, visible: "web",
          description: "Objects whose stain is baked, one task each: a JSON list of names, the objects with Madder Stain enabled" },
        { key: "blendfile", type: "string", required: true, visible: "web",
          description: "Path of the .blend file on the shared storage" },
        { key: "format", type: "string", required: true, eval: "C.scene.render.image_settings.file_format", visible: "web" },
        { key: "scene", type: "string", required: true, eval: "C.scene.name", visible: "web",
          description: "Name of the scene to bake and render" },
    ],
};

// Formats that render a movie, not one image per frame: chunks of frames cannot make one.
const VIDEO_FORMATS = ["FFMPEG", "AVI_RAW", "AVI_JPEG"];

function compileJob(job) {
    const settings = job.settings;
    const objects = objectNames(settings.objects);
    if (!settings.blendfile) {
        throw "Madder: setting 'blendfile' is empty: submit the job from Blender with the file saved";
    }
    if (VIDEO_FORMATS.indexOf(settings.format) >= 0) {
        throw `Madder: setting 'format' is ${settings.format}, a video; choose an image format (e.g. PNG, OPEN_EXR)`;
    }
    if (!Number.isInteger(settings.chunk_size) || settings.chunk_size < 1) {
        throw `Madder: setting 'chunk_size' must be a whole number of frames, at least 1 (got ${settings.chunk_size})`;
    }
    let chunks;
    try {
        chunks = frameChunker(settings.frames, settings.chunk_size);
    } catch (e) {
        throw `Madder: setting 'frames' is not a frame range like '1-250' or '1-10,20' (got '${settings.frames}': ${e})`;
    }
    const before = settings.scene ? ["--scene", settings.scene] : [];
    const enable = ["--python-exit-code", "1", "--python-expr", ENABLE_MADDER];

    const bakes = [];
    for (const name of objects) {
        const task = author.Task(`bake-${name}`, "blender");
        task.addCommand(blender(settings, before.concat(enable, ["--command", "madder", "bake", "--object", name])));
        if (bakes.length > 0) {
            task.addDependency(bakes[bakes.length - 1]); // one save of the .blend at a time
        }
        bakes.push(task);
        job.addTask(task);
    }

    const output = settings.render_output_path;
    if (!output) {
        throw "Madder: setting 'render_output_path' is empty: set 'render_output_root'";
    }
    for (const chunk of chunks) {
        const task = author.Task(`render-${chunk}`, "blender");
        task.addCommand(blender(settings, before.concat(enable, [
            "--render-output", output,
            "--render-format", settings.format,
            "--render-frame", chunk.replaceAll("-", ".."), // Blender's notation for a range
        ]), frameCount(chunk)));
        for (const bake of bakes) {
            task.addDependency(bake);
        }
        job.addTask(task);
    }
}

// A `blender-render` command: the worker runs exe, exeArgs, argsBefore, blendfile, args.
function blender(settings, args, steps) {
    return author.Command("blender-render", {
        exe: "{blender}",
        exeArgs: "{blenderArgs}",
        argsBefore: [],
        blendfile: settings.blendfile,
        args: args,
    }, steps || 0);
}

// The `objects` setting: a JSON list of distinct, non-empty object names.
function objectNames(text) {
    let names;
    try {
        names = JSON.parse(text);
    } catch (e) {
        throw `Madder: setting 'objects' must be a JSON list of object names, e.g. ["Flag"] (got '${text}')`;
    }
    if (!Array.isArray(names) || names.some((n) => typeof n !== "string" || n === "")) {
        throw `Madder: setting 'objects' must be a JSON list of object names, e.g. ["Flag"] (got '${text}')`;
    }
    if (names.length === 0) {
        throw "Madder: no object has Madder Stain enabled (setting 'objects' is empty): enable it on the cloth, or check that Madder is enabled in the Blender that submits";
    }
    const seen = new Set();
    for (const n of names) {
        if (seen.has(n)) {
            throw `Madder: setting 'objects' names '${n}' twice`;
        }
        seen.add(n);
    }
    return names;
}

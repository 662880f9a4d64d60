// Compiles Madder's job type with the stand-in job compiler (flamenco.js) and prints, as
// JSON, its JOB_TYPE and the tasks a worker would run: name, type, the names of the tasks
// it depends on, and each command's argv with the Manager's variables replaced.
// Usage: node compile.js JOB_TYPE_FILE '<settings JSON>' '<variables JSON>'

"use strict";

const { loadJobType, withDefaults, workerArgv } = require("./flamenco.js");

const [file, settings, variables] = process.argv.slice(2);
const { jobType, compile } = loadJobType(file);
let tasks = null;
if (settings) {
    const job = compile(withDefaults(jobType, JSON.parse(settings)));
    const vars = JSON.parse(variables || "{}");
    tasks = job.tasks.map((t) => ({
        name: t.name,
        type: t.type,
        dependencies: t.dependencies.map((d) => d.name),
        commands: t.commands.map((c) => workerArgv(c, vars)),
    }));
}
process.stdout.write(JSON.stringify({ jobType, tasks }));

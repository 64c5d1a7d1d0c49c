// Runs a Flamenco job compiler outside Flamenco with a stubbed `author`, printing the tasks it
// authors as JSON: [{name, type, commands: [{name, params, argv}]}], where argv is the command
// line a Flamenco worker's blender-render command runs (exe, exeArgs, argsBefore, blendfile,
// args). Usage: node flamenco_harness.js JOB_TYPE.js SETTINGS.json BLENDER
"use strict";
const fs = require("fs");
const vm = require("vm");

const [jobTypeFile, settingsFile, blender] = process.argv.slice(2);
const tasks = [];
const author = {
    Task(name, type) {
        const task = { name, type, commands: [] };
        return { addCommand(c) { task.commands.push(c); }, addDependency() {}, _task: task };
    },
    Command(name, params) {
        const exeArgs = (params.exeArgs || "").split(/\s+/).filter((s) => s.length > 0);
        const exe = params.exe == "{blender}" ? blender : params.exe;
        const argv = [exe, ...exeArgs, ...(params.argsBefore || []),
                      ...(params.blendfile ? [params.blendfile] : []), ...(params.args || [])];
        return { name, params, argv };
    },
};
const job = {
    settings: JSON.parse(fs.readFileSync(settingsFile, "utf8")),
    addTask(t) { tasks.push(t._task); },
};
const context = vm.createContext({ author, print: console.log, path: require("path").posix });
vm.runInContext(fs.readFileSync(jobTypeFile, "utf8") + "\nthis.JOB_TYPE = JOB_TYPE;", context,
                { filename: jobTypeFile });
context.compileJob(job);
process.stdout.write(JSON.stringify({ label: context.JOB_TYPE.label, tasks }));

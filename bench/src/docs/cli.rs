//! Markdown from `simbench`'s clap command tree: one section per command and nested
//! subcommand with its description, usage and a table of its arguments (help, possible values,
//! default).

use super::cell;
use clap::{Arg, Command};

/// The command-line reference of `command` (the top-level parser's command).
pub fn render(mut command: Command) -> String {
    command.build();
    let mut out = format!(
        "# Command-line reference\n\n{}\n",
        super::generated_note(&format!("`{}`'s argument parser", command.get_name()))
    );
    if let Some(about) = command.get_about() {
        out += &format!("{about}\n\n");
    }
    out += "Run any command with `--help` for the same text in the terminal.\n\n";
    let mut contents = String::from("Commands:\n\n");
    let mut body = String::new();
    walk(&mut command, &mut Vec::new(), &mut contents, &mut body);
    out + &contents + "\n" + &body
}

/// Appends `cmd` and its subcommands, depth first: a line of the contents and a section each.
/// `path` holds the names of the parent commands.
fn walk(cmd: &mut Command, path: &mut Vec<String>, contents: &mut String, body: &mut String) {
    path.push(cmd.get_name().to_string());
    let full = path.join(" ");
    if path.len() > 1 {
        let indent = "  ".repeat(path.len() - 2);
        *contents += &format!("{indent}- [`{full}`](#{})\n", anchor(&full));
    }
    *body += &section(cmd, &full, path.len() + 1);
    for sub in cmd.get_subcommands_mut() {
        if sub.get_name() != "help" && !sub.is_hide_set() {
            walk(sub, path, contents, body);
        }
    }
    path.pop();
}

/// GitHub's anchor of a heading whose text is `` `full` ``: lower case, spaces as `-`.
fn anchor(full: &str) -> String {
    full.to_lowercase().replace(' ', "-")
}

/// One command's section: heading (level by depth, at most 4), description, usage, arguments.
fn section(cmd: &mut Command, full: &str, depth: usize) -> String {
    let hashes = "#".repeat(depth.clamp(2, 4));
    let mut out = format!("{hashes} `{full}`\n\n");
    if let Some(about) = cmd.get_long_about().or(cmd.get_about()) {
        out += &format!("{about}\n\n");
    }
    let usage = cmd.render_usage().to_string();
    let usage = usage.strip_prefix("Usage: ").unwrap_or(&usage);
    out += &format!("```text\n{}\n```\n\n", usage.trim_end());
    let args: Vec<&Arg> = cmd.get_arguments().filter(|a| shown(a)).collect();
    if !args.is_empty() {
        out += "| Argument | Description | Default |\n|---|---|---|\n";
        for a in args {
            out += &format!("| {} | {} | {} |\n", cell(&arg_name(a)), cell(&arg_help(a)), cell(&arg_default(a)));
        }
        out += "\n";
    }
    out
}

/// Whether an argument belongs in the table (not hidden, not the automatic help and version
/// flags, which every command has).
fn shown(a: &Arg) -> bool {
    !a.is_hide_set() && !matches!(a.get_id().as_str(), "help" | "version")
}

/// `<SCENE>` for a positional argument, `-s, --long <VALUE>` for an option.
fn arg_name(a: &Arg) -> String {
    let value_names: Vec<String> = match a.get_value_names() {
        Some(names) => names.iter().map(|n| format!("<{n}>")).collect(),
        None => vec![format!("<{}>", a.get_id().as_str().to_uppercase())],
    };
    if a.is_positional() {
        return format!("`{}`", value_names.join(" "));
    }
    let mut name = match (a.get_short(), a.get_long()) {
        (Some(s), Some(l)) => format!("-{s}, --{l}"),
        (Some(s), None) => format!("-{s}"),
        (None, Some(l)) => format!("--{l}"),
        (None, None) => a.get_id().to_string(),
    };
    if a.get_action().takes_values() {
        name += &format!(" {}", value_names.join(" "));
    }
    format!("`{name}`")
}

/// The argument's help and, for a closed set of values, the values with their help.
fn arg_help(a: &Arg) -> String {
    let mut help = a.get_long_help().or(a.get_help()).map(ToString::to_string).unwrap_or_default();
    if !a.get_action().takes_values() {
        return help;
    }
    let values: Vec<String> = a
        .get_possible_values()
        .iter()
        .filter(|v| !v.is_hide_set())
        .map(|v| match v.get_help() {
            Some(h) => format!("`{}`: {h}", v.get_name()),
            None => format!("`{}`", v.get_name()),
        })
        .collect();
    if !values.is_empty() {
        help += &format!(" Values: {}.", values.join("; "));
    }
    help
}

/// The default value(s), or empty (also for flags, whose default is being off).
fn arg_default(a: &Arg) -> String {
    if !a.get_action().takes_values() {
        return String::new();
    }
    let defaults: Vec<String> = a.get_default_values().iter().map(|v| format!("`{}`", v.to_string_lossy())).collect();
    defaults.join(" ")
}

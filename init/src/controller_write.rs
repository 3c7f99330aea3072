//! Calibrated values written back into a controller configuration, keeping
//! the file as its author wrote it (order, comments, every other key), so
//! the result diffs against the original in exactly the calibrated numbers.
//!
//! YAML libraries re-emit a document without its comments and layout, so
//! this edits the text: it finds each key by indentation inside the node's
//! `ros__parameters` block (the block style every ros2_control file uses) and
//! replaces the scalar after `key:`, or inserts the key where it belongs.

/// One line's indentation and key (`key:` at the start of its text).
fn key_of(line: &str) -> Option<(usize, &str)> {
    let text = line.trim_start();
    if text.starts_with('#') || text.starts_with('-') {
        return None;
    }
    let indent = line.len() - text.len();
    let colon = text.find(':')?;
    let key = text[..colon].trim().trim_matches(|c| c == '"' || c == '\'');
    Some((indent, key))
}

/// The block of lines below `start` (exclusive) more indented than `indent`:
/// its end (exclusive) and its children's indentation.
fn block(lines: &[String], start: usize, indent: usize) -> (usize, Option<usize>) {
    let mut child = None;
    let mut end = start + 1;
    for (i, l) in lines.iter().enumerate().skip(start + 1) {
        if l.trim().is_empty() || l.trim_start().starts_with('#') {
            continue;
        }
        let ind = l.len() - l.trim_start().len();
        if ind <= indent {
            break;
        }
        child.get_or_insert(ind);
        end = i + 1;
    }
    (end, child)
}

/// The line of `key` directly inside the block under `start` (indentation `indent`).
fn find(lines: &[String], start: usize, indent: usize, key: &str) -> Option<usize> {
    let (end, child) = block(lines, start, indent);
    (start + 1..end)
        .find(|&i| key_of(&lines[i]).is_some_and(|(ind, k)| Some(ind) == child && k == key))
}

/// `line` with the scalar after its key replaced by `value`, keeping a trailing comment.
fn replace_value(line: &str, value: &str) -> String {
    let colon = line.find(':').expect("a key line");
    let rest = &line[colon + 1..];
    // a comment starts at a `#` after whitespace; keep the spacing before it
    let comment = rest.find(" #").map_or("", |c| {
        let scalar = rest[..c].trim_end().len();
        &rest[scalar.max(1)..]
    });
    format!("{}: {value}{comment}", &line[..colon])
}

/// `text` with the node's `ros__parameters` keys (dotted for nested maps) set
/// to `values`. `None` when the file has no such node.
pub fn rewrite(text: &str, node: &str, values: &[(String, String)]) -> Option<String> {
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let top = (0..lines.len())
        .find(|&i| key_of(&lines[i]).is_some_and(|(ind, k)| ind == 0 && k == node))?;
    let params = find(&lines, top, 0, "ros__parameters")?;
    for (key, value) in values {
        let mut at = params;
        let mut indent = key_of(&lines[params]).map_or(0, |k| k.0);
        let parts: Vec<&str> = key.split('.').collect();
        for (n, part) in parts.iter().enumerate() {
            match find(&lines, at, indent, part) {
                Some(i) => {
                    at = i;
                    indent = key_of(&lines[i]).map_or(0, |k| k.0);
                }
                None => {
                    // insert the rest of the path at the end of this block
                    let (end, child) = block(&lines, at, indent);
                    let mut ind = child.unwrap_or(indent + 2);
                    for (insert, (m, p)) in (end..).zip(parts[n..].iter().enumerate()) {
                        let last = n + m + 1 == parts.len();
                        let line = if last {
                            format!("{}{p}: {value}", " ".repeat(ind))
                        } else {
                            format!("{}{p}:", " ".repeat(ind))
                        };
                        lines.insert(insert, line);
                        ind += 2;
                    }
                    at = usize::MAX;
                    break;
                }
            }
        }
        if at != usize::MAX {
            lines[at] = replace_value(&lines[at], value);
        }
    }
    let mut out = lines.join("\n");
    if text.ends_with('\n') {
        out.push('\n');
    }
    Some(out)
}

/// A fresh file with the node's values (when the original is not at hand).
pub fn fresh(node: &str, type_name: &str, values: &[(String, String)]) -> String {
    let mut out = format!("controller_manager:\n  ros__parameters:\n    {node}:\n      type: {type_name}\n\n{node}:\n  ros__parameters:\n");
    let mut open: Vec<String> = Vec::new();
    for (key, value) in values {
        let parts: Vec<&str> = key.split('.').collect();
        let (path, last) = parts.split_at(parts.len() - 1);
        let shared = open.iter().zip(path).take_while(|(a, b)| a == b).count();
        open.truncate(shared);
        for p in &path[shared..] {
            out += &format!("{}{p}:\n", " ".repeat(4 + 2 * open.len()));
            open.push(p.to_string());
        }
        out += &format!("{}{}: {value}\n", " ".repeat(4 + 2 * open.len()), last[0]);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = "controller_manager:\n  ros__parameters:\n    base:\n      type: mecanum_drive_controller/MecanumDriveController\n\nbase:\n  ros__parameters:\n    wheel_radius: 0.05  # from CAD\n    kinematics:\n      wheels_radius: 0.05\n    base_frame_id: chassis\nother:\n  ros__parameters:\n    wheel_radius: 9\n";

    #[test]
    fn a_value_is_replaced_in_its_node_only_and_its_comment_kept() {
        let v = vec![("wheel_radius".to_string(), "0.051".to_string())];
        let out = rewrite(FILE, "base", &v).unwrap();
        assert!(
            out.contains("    wheel_radius: 0.051  # from CAD\n"),
            "{out}"
        );
        assert!(
            out.contains("other:\n  ros__parameters:\n    wheel_radius: 9\n"),
            "{out}"
        );
        assert_eq!(out.lines().count(), FILE.lines().count());
    }

    #[test]
    fn nested_and_missing_keys_land_in_their_block() {
        let v = vec![
            ("kinematics.wheels_radius".to_string(), "0.049".to_string()),
            (
                "kinematics.sum_of_robot_center_projection_on_X_Y_axis".to_string(),
                "0.3".to_string(),
            ),
            ("wheel_separation".to_string(), "0.4".to_string()),
        ];
        let out = rewrite(FILE, "base", &v).unwrap();
        assert!(out.contains("    kinematics:\n      wheels_radius: 0.049\n      sum_of_robot_center_projection_on_X_Y_axis: 0.3\n"), "{out}");
        assert!(
            out.contains("    base_frame_id: chassis\n    wheel_separation: 0.4\nother:"),
            "{out}"
        );
        assert!(rewrite(FILE, "missing", &v).is_none());
    }

    #[test]
    fn a_fresh_file_nests_dotted_keys() {
        let v = vec![
            ("a".to_string(), "1".to_string()),
            ("k.b".to_string(), "2".to_string()),
            ("k.c".to_string(), "3".to_string()),
        ];
        let out = fresh("n", "t/T", &v);
        assert!(
            out.ends_with("n:\n  ros__parameters:\n    a: 1\n    k:\n      b: 2\n      c: 3\n"),
            "{out}"
        );
    }
}

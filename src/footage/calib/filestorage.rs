//! OpenCV's FileStorage documents (what `cv::FileStorage` writes): YAML with OpenCV 4's
//! `%YAML:1.0` header or a standard `%YAML 1.2` one, and XML. Both become one small tree of
//! [`Node`]s, so the camera is read the same way from either.

use std::path::Path;

use yaml_rust2::Yaml;

use crate::error::{Error, Result};
use crate::io::read::read_text;

/// A value in a FileStorage document.
#[derive(Debug, Clone, PartialEq)]
pub enum Node {
    /// Numbers with a shape: a scalar is 1×1, a sequence `n×1`, an `opencv-matrix` rows×cols
    /// (row-major, as OpenCV stores it).
    Numbers {
        rows: usize,
        cols: usize,
        data: Vec<f64>,
    },
    Text(String),
    Map(Vec<(String, Node)>),
    /// A sequence that is not all numbers.
    Seq(Vec<Node>),
}

impl Node {
    fn scalar(v: f64) -> Node {
        Node::Numbers {
            rows: 1,
            cols: 1,
            data: vec![v],
        }
    }

    pub fn get(&self, key: &str) -> Option<&Node> {
        match self {
            Node::Map(entries) => entries.iter().find(|(k, _)| k == key).map(|(_, v)| v),
            _ => None,
        }
    }

    pub fn keys(&self) -> Vec<&str> {
        match self {
            Node::Map(entries) => entries.iter().map(|(k, _)| k.as_str()).collect(),
            _ => Vec::new(),
        }
    }

    /// An `opencv-matrix` map (`rows`, `cols`, `data`) as numbers; any other node unchanged.
    fn into_matrix(self, path: &Path, field: &str) -> Result<Node> {
        let is_matrix = matches!(&self, Node::Map(_))
            && ["rows", "cols", "data"]
                .iter()
                .all(|k| self.get(k).is_some());
        if !is_matrix {
            return Ok(self);
        }
        let count = |k: &str| -> Result<usize> {
            match self.get(k) {
                Some(Node::Numbers { data, .. })
                    if data.len() == 1
                        && data[0] >= 0.0
                        && data[0].fract() == 0.0
                        && data[0] <= 1e6 =>
                {
                    Ok(data[0] as usize)
                }
                _ => Err(Error::invalid(
                    path,
                    format!("{field}.{k}"),
                    "must be a whole number of 0 to 1000000",
                )),
            }
        };
        let (rows, cols) = (count("rows")?, count("cols")?);
        let data = match self.get("data") {
            Some(Node::Numbers { data, .. }) => data.clone(),
            _ => {
                return Err(Error::invalid(
                    path,
                    format!("{field}.data"),
                    "must be a list of numbers",
                ));
            }
        };
        // Multi-channel matrices (dt "3d": one rvec as a 1×1 three-channel matrix) hold
        // rows·cols·channels numbers.
        if rows * cols == 0 || data.len() % (rows * cols) != 0 {
            return Err(Error::invalid(
                path,
                format!("{field}.data"),
                format!("holds {} numbers for a {rows}x{cols} matrix", data.len()),
            ));
        }
        let channels = data.len() / (rows * cols);
        Ok(Node::Numbers {
            rows,
            cols: cols * channels,
            data,
        })
    }
}

/// Read a FileStorage file (YAML or XML, told apart by its first characters) as a map.
pub fn read(path: &Path) -> Result<Node> {
    let text = read_text(path, "calibration file")?;
    let trimmed = text.trim_start_matches('\u{feff}').trim_start();
    if trimmed.starts_with('<') {
        parse_xml(trimmed, path)
    } else {
        parse_yaml(trimmed, path)
    }
}

pub fn parse_yaml(text: &str, path: &Path) -> Result<Node> {
    // OpenCV 4 writes `%YAML:1.0`, which is not a YAML directive; drop any %YAML line (the
    // content is the same in every version OpenCV writes).
    let body: String = text
        .lines()
        .map(|l| if l.starts_with("%YAML") { "" } else { l })
        .collect::<Vec<_>>()
        .join("\n");
    refuse_aliases(&body, path)?;
    let docs = yaml_rust2::YamlLoader::load_from_str(&body)
        .map_err(|e| Error::invalid(path, ".", format!("is not YAML OpenCV can write: {e}")))?;
    let doc = docs
        .into_iter()
        .next()
        .ok_or_else(|| Error::invalid(path, ".", "the YAML document is empty"))?;
    let node = from_yaml(doc, path, "")?;
    match node {
        Node::Map(_) => Ok(node),
        _ => Err(Error::invalid(
            path,
            ".",
            "the document is not a map of named values",
        )),
    }
}

/// OpenCV never writes YAML aliases (`*name`), and the loader copies each one in full, so a
/// few hundred bytes of nested aliases would grow into gigabytes: refuse them before loading.
fn refuse_aliases(body: &str, path: &Path) -> Result<()> {
    let mut parser = yaml_rust2::parser::Parser::new_from_str(body);
    loop {
        match parser.next_token() {
            Ok((yaml_rust2::parser::Event::StreamEnd, _)) => return Ok(()),
            Ok((yaml_rust2::parser::Event::Alias(_), mark)) => {
                return Err(Error::invalid(
                    path,
                    ".",
                    format!(
                        "line {}: a YAML alias (*name); OpenCV never writes them: write the values out",
                        mark.line()
                    ),
                ));
            }
            Ok(_) => {}
            Err(e) => {
                return Err(Error::invalid(
                    path,
                    ".",
                    format!("is not YAML OpenCV can write: {e}"),
                ));
            }
        }
    }
}

fn from_yaml(y: Yaml, path: &Path, field: &str) -> Result<Node> {
    let join = |k: &str| {
        if field.is_empty() {
            k.to_string()
        } else {
            format!("{field}.{k}")
        }
    };
    Ok(match y {
        Yaml::Integer(i) => Node::scalar(i as f64),
        Yaml::Real(s) => Node::scalar(number(&s).ok_or_else(|| {
            Error::invalid(
                path,
                field,
                format!("`{}` is not a number", crate::io::read::quote(&s)),
            )
        })?),
        Yaml::String(s) => match number(&s) {
            // OpenCV writes `1.` and `.5`, which some YAML schemas read as text.
            Some(v) if field.contains("data[") => Node::scalar(v),
            _ => Node::Text(s),
        },
        Yaml::Boolean(b) => Node::Text(b.to_string()),
        Yaml::Null | Yaml::BadValue | Yaml::Alias(_) => Node::Text(String::new()),
        Yaml::Array(items) => {
            let nodes: Vec<Node> = items
                .into_iter()
                .enumerate()
                .map(|(i, v)| from_yaml(v, path, &format!("{field}[{i}]")))
                .collect::<Result<_>>()?;
            numbers_of(nodes)
        }
        Yaml::Hash(map) => {
            let mut entries = Vec::with_capacity(map.len());
            for (k, v) in map {
                let key = match k {
                    Yaml::String(s) => s,
                    Yaml::Integer(i) => i.to_string(),
                    other => format!("{other:?}"),
                };
                let child = from_yaml(v, path, &join(&key))?.into_matrix(path, &join(&key))?;
                entries.push((key, child));
            }
            Node::Map(entries)
        }
    })
}

/// A sequence of scalars becomes an `n×1` column of numbers.
fn numbers_of(nodes: Vec<Node>) -> Node {
    let scalars: Option<Vec<f64>> = nodes
        .iter()
        .map(|n| match n {
            Node::Numbers { data, .. } if data.len() == 1 => Some(data[0]),
            _ => None,
        })
        .collect();
    match scalars {
        Some(data) if !data.is_empty() => Node::Numbers {
            rows: data.len(),
            cols: 1,
            data,
        },
        _ => Node::Seq(nodes),
    }
}

/// A number as OpenCV writes one (`1.`, `.5`, `-1.2e-05`, `.Nan`, `.Inf`).
fn number(s: &str) -> Option<f64> {
    let t = s.trim();
    match t.to_ascii_lowercase().as_str() {
        ".nan" => return Some(f64::NAN),
        ".inf" | "+.inf" => return Some(f64::INFINITY),
        "-.inf" => return Some(f64::NEG_INFINITY),
        _ => {}
    }
    if t.is_empty()
        || !t
            .bytes()
            .all(|b| b.is_ascii_digit() || b"+-.eE".contains(&b))
    {
        return None;
    }
    t.parse().ok()
}

pub fn parse_xml(text: &str, path: &Path) -> Result<Node> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::invalid(path, ".", format!("is not XML: {e}")))?;
    let root = doc.root_element();
    if root.tag_name().name() != "opencv_storage" {
        return Err(Error::invalid(
            path,
            root.tag_name().name(),
            "an OpenCV XML file has <opencv_storage> at its root",
        ));
    }
    from_xml(root, path, "", 0)
}

/// FileStorage documents nest a few levels; a hostile one is refused before it exhausts the
/// stack.
const MAX_DEPTH: usize = 64;

fn from_xml(el: roxmltree::Node, path: &Path, field: &str, depth: usize) -> Result<Node> {
    if depth > MAX_DEPTH {
        return Err(Error::invalid(
            path,
            field,
            format!("nests deeper than {MAX_DEPTH} levels"),
        ));
    }
    let children: Vec<roxmltree::Node> = el.children().filter(|c| c.is_element()).collect();
    if children.is_empty() {
        let text = el.text().unwrap_or("").trim();
        let words: Vec<&str> = text.split_whitespace().collect();
        let values: Option<Vec<f64>> = words.iter().map(|w| number(w)).collect();
        return Ok(match values {
            Some(data) if !data.is_empty() => Node::Numbers {
                rows: data.len(),
                cols: 1,
                data,
            },
            _ => Node::Text(text.trim_matches('"').to_string()),
        });
    }
    let mut entries = Vec::with_capacity(children.len());
    for (i, c) in children.into_iter().enumerate() {
        // Sequence items are written as <_>.
        let key = match c.tag_name().name() {
            "_" => i.to_string(),
            k => k.to_string(),
        };
        let sub = if field.is_empty() {
            key.clone()
        } else {
            format!("{field}.{key}")
        };
        let child = from_xml(c, path, &sub, depth + 1)?.into_matrix(path, &sub)?;
        entries.push((key, child));
    }
    Ok(Node::Map(entries))
}

#[cfg(test)]
mod tests {
    use super::*;

    const YAML4: &str = "%YAML:1.0\n---\nimage_width: 1920\nimage_height: 1080\n\
camera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1.4e+03, 0., 9.595e+02, 0.,\n       1.4e+03, 5.395e+02, 0., 0., 1. ]\n\
distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n   data: [ -1.0e-01, .5, 0., 0., 0. ]\n\
image_size: [ 1920, 1080 ]\ncalibration_time: \"Wed Dec  2\"\n";

    const XML: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<image_width>1920</image_width>
<camera_matrix type_id="opencv-matrix">
  <rows>3</rows>
  <cols>3</cols>
  <dt>d</dt>
  <data>
    1.4e+03 0. 9.595e+02 0. 1.4e+03 5.395e+02 0. 0. 1.</data></camera_matrix>
<rvec type_id="opencv-matrix"><rows>1</rows><cols>1</cols><dt>"3d"</dt><data>0.1 0.2 0.3</data></rvec>
</opencv_storage>
"#;

    #[test]
    fn opencv4_yaml_and_xml_read_alike() {
        let p = Path::new("c.yml");
        let y = parse_yaml(YAML4, p).unwrap();
        let x = parse_xml(XML, p).unwrap();
        for n in [&y, &x] {
            let Some(Node::Numbers { rows, cols, data }) = n.get("camera_matrix") else {
                panic!("{n:?}")
            };
            assert_eq!((*rows, *cols), (3, 3));
            assert_eq!(data[2], 959.5);
            assert_eq!(data[8], 1.0);
        }
        assert_eq!(
            y.get("distortion_coefficients"),
            Some(&Node::Numbers {
                rows: 1,
                cols: 5,
                data: vec![-0.1, 0.5, 0.0, 0.0, 0.0]
            })
        );
        assert_eq!(
            y.get("image_size"),
            Some(&Node::Numbers {
                rows: 2,
                cols: 1,
                data: vec![1920.0, 1080.0]
            })
        );
        assert_eq!(
            y.get("calibration_time"),
            Some(&Node::Text("Wed Dec  2".into()))
        );
        assert_eq!(
            x.get("rvec"),
            Some(&Node::Numbers {
                rows: 1,
                cols: 3,
                data: vec![0.1, 0.2, 0.3]
            })
        );
        // OpenCV 5 writes a standard directive.
        let y5 = parse_yaml(&YAML4.replace("%YAML:1.0", "%YAML 1.2"), p).unwrap();
        assert_eq!(y5, y);
    }

    #[test]
    fn a_bad_matrix_names_its_field() {
        let bad = "%YAML:1.0\n---\nK: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n   data: [ 1., 2. ]\n";
        let e = parse_yaml(bad, Path::new("c.yml")).unwrap_err().to_string();
        assert!(
            e.contains("`K.data`") && e.contains("2 numbers for a 3x3"),
            "{e}"
        );
        let e = parse_xml("<a/>", Path::new("c.xml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("opencv_storage"), "{e}");
        let e = parse_yaml("[1, 2", Path::new("c.yml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("c.yml") && e.contains("not YAML"), "{e}");
    }
}

//! docs/protocol.md is the contract a program outside the project implements to take a role in a
//! run. This test reads its tables and checks them against the code:
//!
//! * each message table (`### <Type>`, columns `field | offset | type | meaning`): every field
//!   at its offset (`offset_of!`) with its type, no field of the struct left out or invented, the
//!   size and alignment, and the iceoryx2 type name, as iceoryx2 records them for a service the
//!   run's transport creates;
//! * the `ctypes` snippets: the fields of the table, in order, with the matching C types;
//! * the service tables: every [`Stream`] and [`Wake`] with its name, and the QoS figures
//!   (publishers, subscribers, buffer, nodes; history 0, safe overflow) as iceoryx2 stores them
//!   for services the run's transport creates, for several sizings;
//! * every service name the text mentions is one of those;
//! * the constants, the role codes and the environment variables (in order).
//!
//! The negative test feeds altered copies of the page and asserts that each alteration is
//! reported, so the checks cannot pass vacuously.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};

use fdi_common::scenario::{ClockMode, MAX_DOF};
use fdi_runtime::ipc::{
    AlarmMsg, ControlMsg, ControllerInMsg, ControllerOutMsg, Local, MeasurementMsg, Payload, Role,
    Sizing, StatusMsg, Stream, TorqueMsg, Transport, Wake,
};
use fdi_runtime::process::external::{ExternalKind, ENV_VARS, MONITOR_LAG};
use iceoryx2::prelude::{
    local, Config, FileName, Node, NodeBuilder, PortFactory as _, SemanticString as _, ServiceName,
};
use iceoryx2::service::static_config::message_type_details::TypeDetail;

fn read_doc() -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/protocol.md");
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

// ---------------------------------------------------------------------------------------------
// The page's tables

/// A Markdown table of the page, with the heading it is under and the line before it.
#[derive(Debug, Clone)]
struct Table {
    heading: String,
    /// The last non-blank line before the table, under the same heading.
    lead: String,
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

/// The cells of a table line, trimmed; a cell that is one code span loses its backticks.
fn cells(line: &str) -> Vec<String> {
    let inner = line.trim();
    let inner = inner.strip_prefix('|').unwrap_or(inner);
    let inner = inner.strip_suffix('|').unwrap_or(inner);
    inner
        .split('|')
        .map(|c| {
            let c = c.trim();
            match c.strip_prefix('`').and_then(|c| c.strip_suffix('`')) {
                Some(code) if !code.contains('`') => code.to_string(),
                _ => c.to_string(),
            }
        })
        .collect()
}

fn is_separator(line: &str) -> bool {
    let l = line.trim();
    l.starts_with('|') && l.contains('-') && l.chars().all(|c| matches!(c, '|' | '-' | ':' | ' '))
}

/// Every table of `doc` outside code blocks.
fn tables(doc: &str) -> Vec<Table> {
    let lines: Vec<&str> = doc.lines().map(str::trim_end).collect();
    let mut out = Vec::new();
    let (mut heading, mut lead) = (String::new(), String::new());
    let mut fenced = false;
    let mut i = 0;
    while i < lines.len() {
        let line = lines[i];
        i += 1;
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if fenced {
            continue;
        }
        if line.starts_with('#') {
            heading = line.trim_start_matches('#').trim().to_string();
            lead.clear();
            continue;
        }
        if line.starts_with('|') && lines.get(i).is_some_and(|l| is_separator(l)) {
            let header = cells(line);
            let mut rows = Vec::new();
            i += 1;
            while i < lines.len() && lines[i].starts_with('|') {
                rows.push(cells(lines[i]));
                i += 1;
            }
            out.push(Table {
                heading: heading.clone(),
                lead: std::mem::take(&mut lead),
                header,
                rows,
            });
            continue;
        }
        if !line.trim().is_empty() {
            lead = line.trim().to_string();
        }
    }
    out
}

/// The tables whose first column is `first`.
fn tables_with(doc: &str, first: &str) -> Vec<Table> {
    tables(doc)
        .into_iter()
        .filter(|t| t.header.first().is_some_and(|h| h == first))
        .collect()
}

/// The rows of the one table whose first column is `first`, each with as many cells as the
/// header (a malformed row is an error).
fn rows_of(doc: &str, first: &str, errors: &mut Vec<String>) -> Vec<Vec<String>> {
    let found = tables_with(doc, first);
    let [table] = found.as_slice() else {
        errors.push(format!(
            "{} tables whose first column is `{first}`, expected one",
            found.len()
        ));
        return Vec::new();
    };
    let mut rows = Vec::new();
    for row in &table.rows {
        if row.len() == table.header.len() {
            rows.push(row.clone());
        } else {
            errors.push(format!(
                "table `{first}`: row {row:?} has {} cells, the header {}",
                row.len(),
                table.header.len()
            ));
        }
    }
    rows
}

// ---------------------------------------------------------------------------------------------
// iceoryx2: what the run's transport creates, read back through a node of our own

static NEXT_PREFIX: AtomicUsize = AtomicUsize::new(0);

/// A run prefix no other check of this process uses.
fn fresh_prefix() -> String {
    format!(
        "fdiproto{}_{}_",
        std::process::id(),
        NEXT_PREFIX.fetch_add(1, Ordering::Relaxed)
    )
}

/// A node of the run `prefix` (process-local services), configured as docs/protocol.md tells a
/// program to: iceoryx2's defaults with `global.prefix`.
fn raw_node(prefix: &str) -> Node<local::Service> {
    let mut config = Config::default();
    config.global.prefix = FileName::new(prefix.as_bytes()).expect("prefix");
    NodeBuilder::new()
        .config(&config)
        .create::<local::Service>()
        .expect("node")
}

fn service_name(name: &str) -> ServiceName {
    ServiceName::new(name).expect("service name")
}

/// Type name, size and alignment of a payload or header, as iceoryx2 records it.
#[derive(Debug, Clone, PartialEq, Eq)]
struct TypeDetails {
    name: String,
    size: usize,
    align: usize,
}

fn details(t: &TypeDetail) -> TypeDetails {
    TypeDetails {
        name: t.type_name().to_string(),
        size: t.size(),
        align: t.alignment(),
    }
}

/// The payload's and the user header's type details of a service of `T` the run's transport
/// creates: what a program's `open()` is compared with.
fn service_types<T: Payload>() -> (TypeDetails, TypeDetails) {
    let prefix = fresh_prefix();
    let run = Local::open(&prefix, "run", Sizing::new(1, 1)).expect("run node");
    let _port = run.subscriber::<T>(Stream::Status).expect("service");
    let node = raw_node(&prefix);
    let service = node
        .service_builder(&service_name(&Stream::Status.service_name()))
        .publish_subscribe::<T>()
        .open()
        .expect("opening the run's service");
    let d = service.static_config().message_type_details();
    (details(&d.payload), details(&d.user_header))
}

/// The QoS of a publish-subscribe service as iceoryx2 stores it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct PubSubQos {
    publishers: usize,
    subscribers: usize,
    buffer: usize,
    nodes: usize,
    history: usize,
    safe_overflow: bool,
}

/// The QoS of `stream` (payload `T`) as the run's transport (`run`) creates it.
fn pubsub_qos<T: Payload>(run: &Local, node: &Node<local::Service>, stream: Stream) -> PubSubQos {
    let _port = run.subscriber::<T>(stream).expect("subscriber");
    let service = node
        .service_builder(&service_name(&stream.service_name()))
        .publish_subscribe::<T>()
        .open()
        .expect("opening the run's service");
    let c = service.static_config();
    PubSubQos {
        publishers: c.max_publishers(),
        subscribers: c.max_subscribers(),
        buffer: c.subscriber_max_buffer_size(),
        nodes: c.max_nodes(),
        history: c.history_size(),
        safe_overflow: c.has_safe_overflow(),
    }
}

/// (max notifiers, max listeners, max nodes) of `wake` as the run's transport creates it.
fn event_qos(run: &Local, node: &Node<local::Service>, wake: Wake) -> (usize, usize, usize) {
    let _listener = run.waker(wake).expect("listener");
    let service = node
        .service_builder(&service_name(&wake.service_name()))
        .event()
        .open()
        .expect("opening the run's event service");
    let c = service.static_config();
    (c.max_notifiers(), c.max_listeners(), c.max_nodes())
}

// ---------------------------------------------------------------------------------------------
// Message layouts

#[derive(Debug, Clone)]
struct Field {
    name: &'static str,
    offset: usize,
    size: usize,
    /// `std::any::type_name` of the field's type: `u64`, `[f64; 7]`.
    ty: &'static str,
}

#[derive(Debug, Clone)]
struct Layout {
    name: &'static str,
    size: usize,
    align: usize,
    /// The payload's type details in iceoryx2.
    payload: TypeDetails,
    /// The user header's type details in iceoryx2.
    user_header: TypeDetails,
    fields: Vec<Field>,
}

fn field_size<S, F>(_: fn(&S) -> &F) -> usize {
    std::mem::size_of::<F>()
}

fn field_type<S, F>(_: fn(&S) -> &F) -> &'static str {
    std::any::type_name::<F>()
}

/// The layout of struct `$t`, whose fields are listed: the destructuring below fails to compile
/// when the struct gains a field the list lacks.
macro_rules! layout {
    ($t:ident { $($f:ident),+ $(,)? }) => {{
        fn every_field(m: $t) {
            let $t { $($f: _),+ } = m;
        }
        let _: fn($t) = every_field;
        let (payload, user_header) = service_types::<$t>();
        Layout {
            name: stringify!($t),
            size: std::mem::size_of::<$t>(),
            align: std::mem::align_of::<$t>(),
            payload,
            user_header,
            fields: vec![$(Field {
                name: stringify!($f),
                offset: std::mem::offset_of!($t, $f),
                size: field_size::<$t, _>(|m| &m.$f),
                ty: field_type::<$t, _>(|m| &m.$f),
            }),+],
        }
    }};
}

fn layouts() -> Vec<Layout> {
    vec![
        layout!(MeasurementMsg {
            seq,
            agent,
            dof,
            t,
            y,
            yd,
            agent_sent_ns,
            attacker_received_ns,
            attacker_sent_ns,
            flags,
            reserved,
        }),
        layout!(TorqueMsg {
            seq,
            agent,
            dof,
            t_send,
            u,
            agent_sent_ns,
            attacker_received_ns,
            attacker_sent_ns,
            center_received_ns,
            center_sent_ns,
            held_s,
            flags,
            reserved,
        }),
        layout!(ControlMsg {
            command,
            reserved,
            epoch_ns,
        }),
        layout!(StatusMsg {
            role,
            agent,
            kind,
            reserved,
            tick,
        }),
        layout!(AlarmMsg {
            seq,
            agent,
            alarm,
            statistic,
            monitor_sent_ns,
        }),
        layout!(ControllerInMsg {
            seq,
            agent,
            dof,
            t,
            tau,
            y,
            yd,
            q_d,
            qd_d,
            qdd_d,
            e_u,
            inertia_ref,
            inverse_inertia_ref,
            inertia,
            bias,
            center_sent_ns,
            flags,
            reserved,
        }),
        layout!(ControllerOutMsg {
            seq,
            agent,
            dof,
            u,
            s_hat,
            controller_sent_ns,
            flags,
            reserved,
        }),
    ]
}

/// `type name `X`, N bytes, alignment A` → (X, N, A).
fn type_line(line: &str) -> Option<(String, usize, usize)> {
    let rest = line.strip_prefix("type name `")?;
    let (name, rest) = rest.split_once('`')?;
    let (size, align) = rest.strip_prefix(", ")?.split_once(" bytes, alignment ")?;
    Some((
        name.to_string(),
        size.parse().ok()?,
        align.trim().parse().ok()?,
    ))
}

/// A documented Rust type → (its `std::any::type_name`, its size). `[f64; MAX_DOF]` is
/// `[f64; 7]`.
fn doc_type(s: &str) -> Option<(String, usize)> {
    let scalar = |t: &str| match t {
        "u8" => Some(1),
        "u16" | "i16" => Some(2),
        "u32" | "i32" | "f32" => Some(4),
        "u64" | "i64" | "f64" => Some(8),
        _ => None,
    };
    if let Some(inner) = s.strip_prefix('[').and_then(|r| r.strip_suffix(']')) {
        let (elem, count) = inner.split_once(';')?;
        let (elem, count) = (elem.trim(), count.trim());
        let n = if count == "MAX_DOF" {
            MAX_DOF
        } else {
            count.parse().ok()?
        };
        return Some((format!("[{elem}; {n}]"), scalar(elem)? * n));
    }
    Some((s.to_string(), scalar(s)?))
}

fn check_layouts(doc: &str, layouts: &[Layout]) -> Vec<String> {
    let mut errors = Vec::new();
    let mut seen = BTreeSet::new();
    let layout_tables = tables(doc)
        .into_iter()
        .filter(|t| t.header == ["field", "offset", "type", "meaning"]);
    for t in layout_tables {
        let Some(l) = layouts.iter().find(|l| l.name == t.heading) else {
            errors.push(format!(
                "a layout table under `{}`, which is none of the message types",
                t.heading
            ));
            continue;
        };
        if !seen.insert(l.name) {
            errors.push(format!("{}: two layout tables", l.name));
        }
        match type_line(&t.lead) {
            None => errors.push(format!(
                "{}: the line before its table is not \"type name `…`, N bytes, alignment A\": {:?}",
                l.name, t.lead
            )),
            Some((name, size, align)) => {
                if name != l.payload.name {
                    errors.push(format!(
                        "{}: type name `{name}` documented, iceoryx2 has `{}`",
                        l.name, l.payload.name
                    ));
                }
                if size != l.size || size != l.payload.size {
                    errors.push(format!(
                        "{}: {size} bytes documented, size_of says {} (iceoryx2 {})",
                        l.name, l.size, l.payload.size
                    ));
                }
                if align != l.align || align != l.payload.align {
                    errors.push(format!(
                        "{}: alignment {align} documented, align_of says {} (iceoryx2 {})",
                        l.name, l.align, l.payload.align
                    ));
                }
            }
        }
        let mut documented = BTreeSet::new();
        let mut spans = Vec::new();
        for row in &t.rows {
            let [name, offset, ty, _meaning] = row.as_slice() else {
                errors.push(format!("{}: row {row:?} has not 4 cells", l.name));
                continue;
            };
            if !documented.insert(name.clone()) {
                errors.push(format!("{}.{name}: documented twice", l.name));
            }
            let Some(f) = l.fields.iter().find(|f| f.name == name) else {
                errors.push(format!(
                    "{}.{name}: documented, but the struct has no such field",
                    l.name
                ));
                continue;
            };
            let offset = match offset.parse::<usize>() {
                Ok(o) if o == f.offset => Some(o),
                Ok(o) => {
                    errors.push(format!(
                        "{}.{name}: offset {o} documented, offset_of! says {}",
                        l.name, f.offset
                    ));
                    Some(o)
                }
                Err(_) => {
                    errors.push(format!(
                        "{}.{name}: offset {offset:?} is not a number",
                        l.name
                    ));
                    None
                }
            };
            let Some((canonical, size)) = doc_type(ty) else {
                errors.push(format!("{}.{name}: unknown type `{ty}`", l.name));
                continue;
            };
            if size != f.size {
                errors.push(format!(
                    "{}.{name}: type `{ty}` has {size} bytes, the field {}",
                    l.name, f.size
                ));
            }
            if canonical != f.ty {
                errors.push(format!(
                    "{}.{name}: type `{ty}` documented, the field is `{}`",
                    l.name, f.ty
                ));
            }
            if let Some(o) = offset {
                spans.push((o, size, name.clone()));
            }
        }
        for f in &l.fields {
            if !documented.contains(f.name) {
                errors.push(format!(
                    "{}.{}: a field of the struct the table leaves out",
                    l.name, f.name
                ));
            }
        }
        spans.sort();
        let mut end = 0;
        for (o, size, name) in &spans {
            if *o < end {
                errors.push(format!("{}.{name}: overlaps the field before it", l.name));
            }
            end = end.max(o + size);
        }
        let covered: usize = spans.iter().map(|s| s.1).sum();
        if end > l.size || covered != l.size {
            errors.push(format!(
                "{}: the documented fields cover {covered} bytes up to byte {end}, of {} \
                 (the page says no message has padding)",
                l.name, l.size
            ));
        }
        let header = &l.user_header;
        let line = format!(
            "type name `{}`, {} bytes, alignment {}",
            header.name, header.size, header.align
        );
        if !doc.contains(&line) {
            errors.push(format!(
                "{}: its user header is {line:?}, which the page does not say",
                l.name
            ));
        }
    }
    for l in layouts {
        if !seen.contains(l.name) {
            errors.push(format!("{0}: no `### {0}` layout table", l.name));
        }
    }
    errors
}

/// Every `class X(ctypes.Structure)` of the page's Python blocks whose X is a message: its
/// fields, in order, with the C type of each field's Rust type; its `type_name()`.
fn check_python_snippets(doc: &str, layouts: &[Layout]) -> Vec<String> {
    let mut errors = Vec::new();
    let mut found = 0;
    for (i, block) in doc.split("```").enumerate() {
        if i % 2 == 0 || !block.starts_with("python") {
            continue;
        }
        let max_dof = block
            .lines()
            .find_map(|l| l.trim().strip_prefix("MAX_DOF = "))
            .and_then(|v| v.trim().parse::<usize>().ok());
        let ctype = |c: &str| -> Option<String> {
            let c = c.trim();
            match c {
                "ctypes.c_uint64" => Some("u64".into()),
                "ctypes.c_uint32" => Some("u32".into()),
                "ctypes.c_double" => Some("f64".into()),
                _ => {
                    let (elem, n) = c.split_once('*')?;
                    if elem.trim() != "ctypes.c_double" {
                        return None;
                    }
                    let n = match n.trim() {
                        "MAX_DOF" => max_dof?,
                        n => n.parse().ok()?,
                    };
                    Some(format!("[f64; {n}]"))
                }
            }
        };
        for class in block.split("\nclass ").skip(1) {
            let Some((name, body)) = class.split_once("(ctypes.Structure):") else {
                continue;
            };
            let Some(l) = layouts.iter().find(|l| l.name == name) else {
                continue;
            };
            found += 1;
            let body = body.split("\n\n\n").next().unwrap_or(body);
            let mut fields = Vec::new();
            for line in body.lines() {
                let Some(rest) = line.trim().strip_prefix("(\"") else {
                    continue;
                };
                let Some((field, rest)) = rest.split_once("\",") else {
                    errors.push(format!("python {name}: cannot read {line:?}"));
                    continue;
                };
                let c = rest.trim().trim_end_matches(',').trim_end_matches(')');
                match ctype(c) {
                    Some(ty) => fields.push((field.to_string(), ty)),
                    None => errors.push(format!("python {name}.{field}: unknown C type {c:?}")),
                }
            }
            let mut expected: Vec<&Field> = l.fields.iter().collect();
            expected.sort_by_key(|f| f.offset);
            let expected: Vec<(String, String)> = expected
                .iter()
                .map(|f| (f.name.to_string(), f.ty.to_string()))
                .collect();
            if fields != expected {
                errors.push(format!(
                    "python {name}: fields {fields:?}, the struct's in offset order {expected:?}"
                ));
            }
            let returns = format!("return \"{}\"", l.payload.name);
            if !body.contains(&returns) {
                errors.push(format!("python {name}: type_name() does not `{returns}`"));
            }
            for (what, value) in [("sizeof", l.size), ("alignment", l.align)] {
                let claim = format!("ctypes.{what}({name}) == ");
                if let Some(rest) = body.split(&claim).nth(1) {
                    let n: String = rest.chars().take_while(char::is_ascii_digit).collect();
                    if n.parse() != Ok(value) {
                        errors.push(format!("python {name}: asserts {what} {n}, it is {value}"));
                    }
                }
            }
        }
    }
    if found == 0 {
        errors.push("no ctypes snippet of a message".into());
    }
    errors
}

// ---------------------------------------------------------------------------------------------
// Services

/// The id standing for `<id>` / `(id)` in the page's names.
const ID: u32 = 7;

/// Every stream; the match fails to compile when [`Stream`] gains a variant the list lacks.
fn every_stream() -> Vec<Stream> {
    fn listed(s: Stream) {
        match s {
            Stream::Measurement
            | Stream::Tampered
            | Stream::Torque(_)
            | Stream::Actuation
            | Stream::Control
            | Stream::Status
            | Stream::ExternalIn
            | Stream::ExternalOut
            | Stream::Alarm
            | Stream::ControllerIn
            | Stream::ControllerOut => {}
        }
    }
    let _: fn(Stream) = listed;
    vec![
        Stream::Measurement,
        Stream::Tampered,
        Stream::Torque(ID),
        Stream::Actuation,
        Stream::Control,
        Stream::Status,
        Stream::ExternalIn,
        Stream::ExternalOut,
        Stream::Alarm,
        Stream::ControllerIn,
        Stream::ControllerOut,
    ]
}

/// Every wake-up event; the match fails to compile when [`Wake`] gains a variant the list lacks.
fn every_wake() -> Vec<Wake> {
    fn listed(w: Wake) {
        match w {
            Wake::Agent(_)
            | Wake::Attacker
            | Wake::Center
            | Wake::Launcher
            | Wake::ExternalAttacker
            | Wake::Monitor
            | Wake::ExternalController => {}
        }
    }
    let _: fn(Wake) = listed;
    vec![
        Wake::Agent(ID),
        Wake::Attacker,
        Wake::Center,
        Wake::Launcher,
        Wake::ExternalAttacker,
        Wake::Monitor,
        Wake::ExternalController,
    ]
}

/// A documented name with `<id>` standing for [`ID`].
fn with_id(name: &str) -> String {
    name.replace("<id>", &ID.to_string())
}

/// A QoS figure of the page: a sum of products of integers, `n` and `burst` (`n·burst`,
/// `n + 6`).
fn eval(expr: &str, n: usize, burst: usize) -> Option<usize> {
    expr.split('+')
        .map(|term| {
            term.split(['·', '*', '×'])
                .map(|f| match f.trim() {
                    "n" => Some(n),
                    "burst" => Some(burst),
                    x => x.parse().ok(),
                })
                .product::<Option<usize>>()
        })
        .sum()
}

/// Sizings the QoS figures are checked for: (agents, messages in flight per agent). Each gives
/// `burst` and `n·burst` values no other figure has.
const SIZINGS: [(usize, usize); 3] = [(1, 1), (4, 7), (3, 100)];

/// `burst` as the page defines it.
fn burst(in_flight: usize) -> usize {
    (4 * in_flight).max(256)
}

fn check_services(doc: &str) -> Vec<String> {
    let mut errors = Vec::new();
    for definition in [
        "in_flight = ceil(τ_max / Δ) + 2",
        "burst = max(4 · in_flight, 256)",
    ] {
        if !doc.contains(definition) {
            errors.push(format!("the page does not define `{definition}`"));
        }
    }
    let paper = fdi_runtime::process::sizing_for(&fdi_common::scenario::paper().expect("paper"));
    let example = format!(
        "n = {}, τ_max = 5 ms, Δ = 1 ms. So in_flight = {}, burst = {}",
        paper.agents,
        paper.in_flight,
        burst(paper.in_flight)
    );
    if !doc.contains(&example) {
        errors.push(format!("the paper's example is not `{example}`"));
    }

    // Names: every variant once, each name as built.
    let streams = rows_of(doc, "service", &mut errors);
    let wakes = rows_of(doc, "event service", &mut errors);
    let mut documented = BTreeSet::new();
    let mut stream_rows = Vec::new();
    for row in &streams {
        let (name, variant) = (&row[0], &row[1]);
        documented.insert(name.clone());
        let Some(s) = every_stream()
            .into_iter()
            .find(|s| format!("Stream::{s:?}") == variant.replace("(id)", &format!("({ID})")))
        else {
            errors.push(format!("`{name}`: `{variant}` is no Stream"));
            continue;
        };
        if with_id(name) != s.service_name() {
            errors.push(format!(
                "`{variant}`: `{name}` documented, service_name() is `{}`",
                s.service_name()
            ));
        }
        stream_rows.push((s, row));
    }
    for s in every_stream() {
        let n = stream_rows.iter().filter(|(x, _)| *x == s).count();
        if n != 1 {
            errors.push(format!("Stream::{s:?} is documented {n} times"));
        }
    }
    let mut wake_rows = Vec::new();
    for row in &wakes {
        let (name, variant) = (&row[0], &row[1]);
        documented.insert(name.clone());
        let Some(w) = every_wake()
            .into_iter()
            .find(|w| format!("Wake::{w:?}") == variant.replace("(id)", &format!("({ID})")))
        else {
            errors.push(format!("`{name}`: `{variant}` is no Wake"));
            continue;
        };
        if with_id(name) != w.service_name() {
            errors.push(format!(
                "`{variant}`: `{name}` documented, service_name() is `{}`",
                w.service_name()
            ));
        }
        wake_rows.push((w, row));
    }
    for w in every_wake() {
        let n = wake_rows.iter().filter(|(x, _)| *x == w).count();
        if n != 1 {
            errors.push(format!("Wake::{w:?} is documented {n} times"));
        }
    }

    // Every service name in the text (in backticks or in quotes) is one of the tables'.
    let known = |name: &str| {
        documented.iter().any(|d| {
            d == name
                || d.strip_suffix("<id>").is_some_and(|stem| {
                    name.strip_prefix(stem)
                        .is_some_and(|id| !id.is_empty() && id.bytes().all(|b| b.is_ascii_digit()))
                })
        })
    };
    for quote in ['`', '"'] {
        let opening = format!("{quote}fdi/");
        for (at, _) in doc.match_indices(&opening) {
            let rest = &doc[at + 1..];
            let name = rest.split(quote).next().unwrap_or(rest);
            if !known(name) {
                errors.push(format!(
                    "the text names `{name}`, which is no service of the tables"
                ));
            }
        }
    }

    // QoS, as the run's transport creates the services.
    for (agents, in_flight) in SIZINGS {
        let prefix = fresh_prefix();
        let run = Local::open(&prefix, "run", Sizing::new(agents, in_flight)).expect("run node");
        let node = raw_node(&prefix);
        let b = burst(in_flight);
        let figure = |what: &str, cell: &str, errors: &mut Vec<String>| {
            let v = eval(cell, agents, b);
            if v.is_none() {
                errors.push(format!("{what}: cannot read the figure `{cell}`"));
            }
            v
        };
        for (s, row) in &stream_rows {
            let [_, _, payload, _, publishers, subscribers, buffer, nodes] = row.as_slice() else {
                errors.push(format!("Stream::{s:?}: row {row:?} has not 8 cells"));
                continue;
            };
            let got = match payload.as_str() {
                "MeasurementMsg" => pubsub_qos::<MeasurementMsg>(&run, &node, *s),
                "TorqueMsg" => pubsub_qos::<TorqueMsg>(&run, &node, *s),
                "ControlMsg" => pubsub_qos::<ControlMsg>(&run, &node, *s),
                "StatusMsg" => pubsub_qos::<StatusMsg>(&run, &node, *s),
                "AlarmMsg" => pubsub_qos::<AlarmMsg>(&run, &node, *s),
                "ControllerInMsg" => pubsub_qos::<ControllerInMsg>(&run, &node, *s),
                "ControllerOutMsg" => pubsub_qos::<ControllerOutMsg>(&run, &node, *s),
                other => {
                    errors.push(format!("Stream::{s:?}: payload `{other}` is no message"));
                    continue;
                }
            };
            let what = format!("Stream::{s:?} with {agents} agents, {in_flight} in flight");
            let expected = (
                figure(&what, publishers, &mut errors),
                figure(&what, subscribers, &mut errors),
                figure(&what, buffer, &mut errors),
                figure(&what, nodes, &mut errors),
            );
            let actual = (
                Some(got.publishers),
                Some(got.subscribers),
                Some(got.buffer),
                Some(got.nodes),
            );
            if expected != actual {
                errors.push(format!(
                    "{what}: (publishers, subscribers, buffer, nodes) documented {expected:?}, \
                     iceoryx2 has {actual:?}"
                ));
            }
            if got.history != 0 || !got.safe_overflow {
                errors.push(format!(
                    "{what}: history {} and safe overflow {}, the page says 0 and on",
                    got.history, got.safe_overflow
                ));
            }
        }
        for (w, row) in &wake_rows {
            let [_, _, _, _, notifiers, listeners, nodes] = row.as_slice() else {
                errors.push(format!("Wake::{w:?}: row {row:?} has not 7 cells"));
                continue;
            };
            let what = format!("Wake::{w:?} with {agents} agents");
            let expected = (
                figure(&what, notifiers, &mut errors),
                figure(&what, listeners, &mut errors),
                figure(&what, nodes, &mut errors),
            );
            let (n, l, m) = event_qos(&run, &node, *w);
            let actual = (Some(n), Some(l), Some(m));
            if expected != actual {
                errors.push(format!(
                    "{what}: (notifiers, listeners, nodes) documented {expected:?}, iceoryx2 \
                     has {actual:?}"
                ));
            }
        }
    }
    errors
}

// ---------------------------------------------------------------------------------------------
// Constants, roles, environment

fn check_constants(doc: &str) -> Vec<String> {
    let mut errors = Vec::new();
    let expected: BTreeMap<&str, u64> = [
        ("MeasurementMsg::GAP", u64::from(MeasurementMsg::GAP)),
        ("TorqueMsg::GAP", u64::from(TorqueMsg::GAP)),
        ("ControlMsg::START", u64::from(ControlMsg::START)),
        ("ControlMsg::STOP", u64::from(ControlMsg::STOP)),
        ("StatusMsg::READY", u64::from(StatusMsg::READY)),
        ("StatusMsg::PROGRESS", u64::from(StatusMsg::PROGRESS)),
        ("StatusMsg::DONE", u64::from(StatusMsg::DONE)),
        ("StatusMsg::LOST", u64::from(StatusMsg::LOST)),
        ("StatusMsg::REJOINED", u64::from(StatusMsg::REJOINED)),
        (
            "ControllerInMsg::MISSING",
            u64::from(ControllerInMsg::MISSING),
        ),
        (
            "ControllerInMsg::REJECTED",
            u64::from(ControllerInMsg::REJECTED),
        ),
        (
            "ControllerOutMsg::ALARM",
            u64::from(ControllerOutMsg::ALARM),
        ),
        (
            "ControllerOutMsg::OWN_ALARM",
            u64::from(ControllerOutMsg::OWN_ALARM),
        ),
        ("MAX_DOF", MAX_DOF as u64),
        ("MONITOR_LAG", MONITOR_LAG),
    ]
    .into_iter()
    .collect();
    let mut documented = BTreeMap::new();
    for row in rows_of(doc, "constant", &mut errors) {
        let value = row[1].parse::<u64>();
        match (expected.get(row[0].as_str()), value) {
            (None, _) => errors.push(format!("constant `{}` is not one the test knows", row[0])),
            (Some(_), Err(_)) => errors.push(format!("constant `{}`: value {:?}", row[0], row[1])),
            (Some(e), Ok(v)) if *e != v => errors.push(format!(
                "constant `{}`: {v} documented, the code has {e}",
                row[0]
            )),
            _ => {}
        }
        if documented.insert(row[0].clone(), ()).is_some() {
            errors.push(format!("constant `{}` documented twice", row[0]));
        }
    }
    for name in expected.keys() {
        if !documented.contains_key(*name) {
            errors.push(format!("constant `{name}` is not documented"));
        }
    }

    let roles: BTreeMap<String, u32> = Role::ALL
        .into_iter()
        .map(|r| (format!("Role::{r:?}"), r.code()))
        .collect();
    for r in Role::ALL {
        assert_eq!(Role::from_code(r.code()), Some(r), "codes are one to one");
    }
    let mut seen = BTreeSet::new();
    for row in rows_of(doc, "role", &mut errors) {
        match (roles.get(&row[0]), row[1].parse::<u32>()) {
            (None, _) => errors.push(format!("`{}` is not in Role::ALL", row[0])),
            (Some(c), Ok(v)) if *c == v => {}
            (Some(c), _) => errors.push(format!(
                "`{}`: code {:?} documented, the code has {c}",
                row[0], row[1]
            )),
        }
        seen.insert(row[0].clone());
    }
    for name in roles.keys() {
        if !seen.contains(name) {
            errors.push(format!("`{name}` is not documented"));
        }
    }
    errors
}

fn check_environment(doc: &str) -> Vec<String> {
    let mut errors = Vec::new();
    let rows = rows_of(doc, "variable", &mut errors);
    let names: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    if names != ENV_VARS {
        errors.push(format!(
            "environment: {names:?} documented, ENV_VARS is {ENV_VARS:?}"
        ));
    }
    let row = |name: &str| rows.iter().find(|r| r[0] == name).map(|r| r[1..].join(" "));
    for (var, values) in [
        (
            "FDI_ROLE",
            &[
                ExternalKind::Attacker.as_str(),
                ExternalKind::Monitor.as_str(),
                ExternalKind::Controller.as_str(),
            ][..],
        ),
        (
            "FDI_CLOCK",
            &[ClockMode::Lockstep.as_str(), ClockMode::Realtime.as_str()][..],
        ),
    ] {
        for v in values {
            if !row(var).is_some_and(|r| r.contains(&format!("`{v}`"))) {
                errors.push(format!("{var}: the value `{v}` is not documented"));
            }
        }
    }
    if !row("FDI_MONITOR_LAG").is_some_and(|r| r.contains(&MONITOR_LAG.to_string())) {
        errors.push(format!("FDI_MONITOR_LAG: {MONITOR_LAG} is not documented"));
    }
    errors
}

/// Everything the page is checked for.
fn check_all(doc: &str, layouts: &[Layout]) -> Vec<String> {
    let mut errors = check_layouts(doc, layouts);
    errors.extend(check_python_snippets(doc, layouts));
    errors.extend(check_services(doc));
    errors.extend(check_constants(doc));
    errors.extend(check_environment(doc));
    errors
}

// ---------------------------------------------------------------------------------------------
// Tests

#[test]
fn the_protocol_page_matches_the_code() {
    let doc = read_doc();
    let found = tables(&doc);
    let big = found.iter().filter(|t| t.rows.len() >= 4).count();
    assert!(
        big >= 5,
        "{big} tables with at least 4 rows in docs/protocol.md (of {})",
        found.len()
    );
    let layouts = layouts();
    let layout_tables = found
        .iter()
        .filter(|t| t.header == ["field", "offset", "type", "meaning"])
        .count();
    assert_eq!(layout_tables, layouts.len(), "one layout table per message");
    let errors = check_all(&doc, &layouts);
    assert!(
        errors.is_empty(),
        "docs/protocol.md differs from the code:\n  {}",
        errors.join("\n  ")
    );
}

#[test]
fn the_payloads_are_what_the_protocol_promises_a_program() {
    for l in layouts() {
        assert!(
            l.payload.name.starts_with("fdi_mas::"),
            "{}: {}",
            l.name,
            l.payload.name
        );
        assert_eq!(
            (l.payload.size, l.payload.align),
            (l.size, l.align),
            "{}: iceoryx2 and the compiler agree",
            l.name
        );
        assert_eq!(
            l.user_header,
            TypeDetails {
                name: "()".into(),
                size: 0,
                align: 1
            },
            "{}: the user header is `()`",
            l.name
        );
    }
}

/// Replaces the first `from` of `doc` with `to`; the alteration must take.
fn altered(doc: &str, from: &str, to: &str) -> String {
    assert!(doc.contains(from), "the page no longer contains {from:?}");
    doc.replacen(from, to, 1)
}

#[test]
fn an_altered_page_is_reported() {
    let doc = read_doc();
    let layouts = layouts();
    assert!(check_all(&doc, &layouts).is_empty(), "the page passes");
    let swapped_env = {
        let dof = doc
            .lines()
            .find(|l| l.starts_with("| `FDI_DOF`"))
            .expect("FDI_DOF row");
        let ticks = doc
            .lines()
            .find(|l| l.starts_with("| `FDI_TICKS`"))
            .expect("FDI_TICKS row");
        altered(
            &doc,
            &format!("{dof}\n{ticks}\n"),
            &format!("{ticks}\n{dof}\n"),
        )
    };
    let tampered_row = doc
        .lines()
        .find(|l| l.starts_with("| `fdi/tampered`"))
        .expect("fdi/tampered row");
    let cases: Vec<(&str, String, &str)> = vec![
        (
            "a wrong offset",
            altered(&doc, "| `dof` | 12 |", "| `dof` | 16 |"),
            "MeasurementMsg.dof: offset 16 documented, offset_of! says 12",
        ),
        (
            "a wrong type",
            altered(&doc, "| `agent` | 8 | `u32` |", "| `agent` | 8 | `u64` |"),
            "MeasurementMsg.agent: type `u64` has 8 bytes, the field 4",
        ),
        (
            "a wrong array length",
            altered(
                &doc,
                "| `y` | 24 | `[f64; 12]` |",
                "| `y` | 24 | `[f64; 5]` |",
            ),
            "MeasurementMsg.y: type `[f64; 5]` has 40 bytes, the field 96",
        ),
        (
            "a field left out",
            altered(&doc, "| `reserved` | 172 | `u32` | 0 |\n", ""),
            "TorqueMsg.reserved: a field of the struct the table leaves out",
        ),
        (
            "a field that does not exist",
            altered(
                &doc,
                "| `monitor_sent_ns` | 24 | `u64` |",
                "| `spare` | 32 | `u64` | spare |\n| `monitor_sent_ns` | 24 | `u64` |",
            ),
            "AlarmMsg.spare: documented, but the struct has no such field",
        ),
        (
            "a wrong type name",
            altered(
                &doc,
                "type name `fdi_mas::AlarmMsg`",
                "type name `fdi_mas::Alarm`",
            ),
            "AlarmMsg: type name `fdi_mas::Alarm` documented",
        ),
        (
            "a wrong size",
            altered(
                &doc,
                "`fdi_mas::StatusMsg`, 24 bytes",
                "`fdi_mas::StatusMsg`, 32 bytes",
            ),
            "StatusMsg: 32 bytes documented",
        ),
        (
            "a ctypes field of another type",
            altered(
                &doc,
                "(\"flags\", ctypes.c_uint32)",
                "(\"flags\", ctypes.c_uint64)",
            ),
            "python MeasurementMsg: fields",
        ),
        (
            "a wrong service name",
            altered(&doc, "| `fdi/alarm` |", "| `fdi/alarms` |"),
            "`Stream::Alarm`: `fdi/alarms` documented",
        ),
        (
            "a service name in the text that does not exist",
            altered(
                &doc,
                "`fdi/wake/monitor` for the monitor",
                "`fdi/wake/monitors` for the monitor",
            ),
            "the text names `fdi/wake/monitors`",
        ),
        (
            "a wrong buffer size",
            altered(
                &doc,
                tampered_row,
                &tampered_row.replace("| n·burst |", "| burst |"),
            ),
            "Stream::Tampered with 4 agents, 7 in flight",
        ),
        (
            "a wrong constant",
            altered(
                &doc,
                "| `StatusMsg::DONE` | 3 |",
                "| `StatusMsg::DONE` | 4 |",
            ),
            "constant `StatusMsg::DONE`: 4 documented, the code has 3",
        ),
        (
            "a wrong role code",
            altered(&doc, "| `Role::Monitor` | 4 |", "| `Role::Monitor` | 5 |"),
            "`Role::Monitor`: code \"5\" documented, the code has 4",
        ),
        (
            "environment variables out of order",
            swapped_env,
            "environment:",
        ),
    ];
    for (what, page, expected) in &cases {
        let errors = check_all(page, &layouts);
        assert!(
            errors.iter().any(|e| e.contains(expected)),
            "{what}: expected a report containing {expected:?}, got {errors:#?}"
        );
    }
}

#[test]
fn the_table_parser_reads_cells_and_skips_code_blocks() {
    let page = "## A\n\ntype name `x`, 8 bytes, alignment 8\n\n| field | offset | type | meaning |\n\
                |---|---|---|---|\n| `a` | 0 | `u64` | first |\n\n```text\n| not | a |\n|---|---|\n```\n";
    let t = tables(page);
    assert_eq!(t.len(), 1);
    assert_eq!(t[0].heading, "A");
    assert_eq!(t[0].lead, "type name `x`, 8 bytes, alignment 8");
    assert_eq!(t[0].rows, vec![vec!["a", "0", "u64", "first"]]);
    assert_eq!(type_line(&t[0].lead), Some(("x".into(), 8, 8)));
    assert_eq!(doc_type("[f64; MAX_DOF]"), Some(("[f64; 12]".into(), 96)));
    assert_eq!(eval("n·burst", 3, 400), Some(1200));
    assert_eq!(eval("n + 6", 3, 400), Some(9));
    assert_eq!(eval("2 · x", 3, 400), None);
}

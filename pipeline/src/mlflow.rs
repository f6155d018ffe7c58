//! `alnlab export mlflow`: a recorded run handed to an MLflow tracking
//! server through its documented REST API (`/api/2.0/mlflow/…`, and the
//! proxied artifact store `/api/2.0/mlflow-artifacts/artifacts/…`), never
//! its storage.
//!
//! Each variant's replicate becomes one MLflow run, under an MLflow
//! experiment named after the alnlab experiment: its resolved parameters
//! (dotted keys), its metrics ([`alnlab_report::metrics`]: figures at
//! step 0, per-epoch training errors and per-horizon closed-loop errors as
//! steps), tags (the alnlab run id, variant and replicate, the git commit as
//! `mlflow.source.git.commit`, the manifest's path and sha256) and, as
//! artifacts, the run record and the report rendered from it.
//!
//! MLflow names allow letters, digits and `_ - . / : space`; any other
//! character (the `@` of `simulator@1/frame`) becomes `_` ([`key`]).
//!
//! Exporting again does not duplicate: a replicate already exported (its
//! MLflow run tagged `alnlab.export = complete`) is skipped; one whose
//! export was cut short is deleted and exported anew.

use std::path::Path;
use std::time::{Duration, UNIX_EPOCH};

use alnlab_common::{Error, Result};
use base64::Engine as _;
use serde_json::{Value, json};

use crate::records::{RunRecord, VariantRecord};

/// MLflow's limits per `runs/log-batch` request.
const PARAMS_PER_BATCH: usize = 100;
const METRICS_PER_BATCH: usize = 1000;
/// MLflow's longest parameter value.
const MAX_PARAM_VALUE: usize = 6000;

/// The tag that marks a finished export.
const EXPORTED_TAG: &str = "alnlab.export";

/// A client of one tracking server.
pub struct Client {
    base: String,
    agent: ureq::Agent,
    authorization: Option<String>,
    /// How long one request may take.
    timeout: Duration,
}

/// How often a request that is safe to repeat (GET, and PUT of an artifact)
/// is tried when the server does not answer or answers 5xx; the waits
/// between tries are 1 s, 2 s, ….
const ATTEMPTS: u32 = 3;

impl Client {
    /// A client of the server at `uri` (`http://host:port`, or https),
    /// authenticated as MLflow's own clients are when the environment says
    /// so: `MLFLOW_TRACKING_TOKEN` (bearer), or `MLFLOW_TRACKING_USERNAME`
    /// and `MLFLOW_TRACKING_PASSWORD` (basic). A request that takes longer
    /// than `timeout` fails.
    pub fn new(uri: &str, timeout: Duration) -> Result<Client> {
        if !(uri.starts_with("http://") || uri.starts_with("https://")) {
            return Err(Error::Invalid(format!(
                "--tracking-uri {uri}: expected the address of an MLflow tracking server, \
                 http://host:port or https://… (alnlab talks to the server's REST API, not to \
                 its storage)"
            )));
        }
        let env = |name: &str| std::env::var(name).ok().filter(|v| !v.is_empty());
        let authorization = match (
            env("MLFLOW_TRACKING_TOKEN"),
            env("MLFLOW_TRACKING_USERNAME"),
            env("MLFLOW_TRACKING_PASSWORD"),
        ) {
            (Some(token), _, _) => Some(format!("Bearer {token}")),
            (None, Some(user), Some(password)) => Some(format!(
                "Basic {}",
                base64::engine::general_purpose::STANDARD.encode(format!("{user}:{password}"))
            )),
            _ => None,
        };
        let agent = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(timeout))
            .build()
            .into();
        Ok(Client {
            base: uri.trim_end_matches('/').to_string(),
            agent,
            authorization,
            timeout,
        })
    }

    /// `request` tried up to [`ATTEMPTS`] times while the server does not
    /// answer or answers with a server error; for requests safe to repeat.
    fn retried(&self, url: &str, request: impl Fn() -> Answer) -> Answer {
        let mut attempt = 1;
        loop {
            let failure = match request() {
                Err(Failure::Unreachable(why)) => why,
                Err(Failure::Refused {
                    status, message, ..
                }) if status >= 500 => {
                    format!("HTTP {status}: {message}")
                }
                answer => return answer,
            };
            if attempt == ATTEMPTS {
                return Err(Failure::Unreachable(format!(
                    "{url}: gave up after {attempt} tries: {failure}"
                )));
            }
            eprintln!("warning: {url}: {failure}; trying again in {attempt} s");
            std::thread::sleep(Duration::from_secs(u64::from(attempt)));
            attempt += 1;
        }
    }

    /// `POST /api/2.0/mlflow/<endpoint>` with a JSON body.
    fn post(&self, endpoint: &str, body: &Value) -> Answer {
        let url = format!("{}/api/2.0/mlflow/{endpoint}", self.base);
        let mut request = self.agent.post(&url);
        if let Some(auth) = &self.authorization {
            request = request.header("Authorization", auth);
        }
        self.answer(&url, request.send_json(body))
    }

    /// `GET /api/2.0/mlflow/<endpoint>?<query>`, retried.
    fn get(&self, endpoint: &str, query: &[(&str, &str)]) -> Answer {
        let url = format!("{}/api/2.0/mlflow/{endpoint}", self.base);
        self.retried(&url, || {
            let mut request = self.agent.get(&url);
            for (k, v) in query {
                request = request.query(*k, *v);
            }
            if let Some(auth) = &self.authorization {
                request = request.header("Authorization", auth);
            }
            self.answer(&url, request.call())
        })
    }

    /// Uploads `bytes` as the artifact at `path` (under the proxied store),
    /// retried: a second upload replaces the first.
    fn put(&self, path: &str, bytes: &[u8]) -> std::result::Result<(), Failure> {
        let url = format!("{}/api/2.0/mlflow-artifacts/artifacts/{path}", self.base);
        self.retried(&url, || {
            let mut request = self.agent.put(&url);
            if let Some(auth) = &self.authorization {
                request = request.header("Authorization", auth);
            }
            self.answer(&url, request.send(bytes))
        })
        .map(|_| ())
    }

    /// The JSON of a 2xx answer, or an error naming the request and what
    /// the server said.
    fn answer(
        &self,
        url: &str,
        response: std::result::Result<ureq::http::Response<ureq::Body>, ureq::Error>,
    ) -> Answer {
        let mut response = response.map_err(|e| {
            Failure::Unreachable(match e {
                ureq::Error::Timeout(_) => format!(
                    "the MLflow server at {} did not answer within {} s (--timeout)",
                    self.base,
                    self.timeout.as_secs_f64()
                ),
                e => format!(
                    "cannot reach the MLflow server at {} ({e}); is `mlflow server` running \
                     there?",
                    self.base
                ),
            })
        })?;
        let status = response.status().as_u16();
        let text = response
            .body_mut()
            .read_to_string()
            .map_err(|e| Failure::Unreachable(format!("{url}: unreadable answer ({e})")))?;
        if (200..300).contains(&status) {
            if text.trim().is_empty() {
                return Ok(json!({}));
            }
            return serde_json::from_str(&text).map_err(|e| {
                Failure::Unreachable(format!(
                    "{url}: the answer is not MLflow's JSON ({e}); is {} an MLflow server?",
                    self.base
                ))
            });
        }
        let said: Value = serde_json::from_str(&text).unwrap_or(Value::Null);
        Err(Failure::Refused {
            status,
            code: said["error_code"].as_str().unwrap_or("").to_string(),
            message: said["message"]
                .as_str()
                .map_or_else(|| text.chars().take(300).collect(), str::to_string),
            url: url.to_string(),
        })
    }
}

/// A request's JSON answer, or why there is none.
type Answer = std::result::Result<Value, Failure>;

/// Why a request failed.
enum Failure {
    /// No answer, or one that is not MLflow's.
    Unreachable(String),
    /// The server said no: its HTTP status, MLflow's error code and message.
    Refused {
        status: u16,
        code: String,
        message: String,
        url: String,
    },
}

impl From<Failure> for Error {
    fn from(failure: Failure) -> Error {
        match failure {
            Failure::Unreachable(message) => Error::Invalid(message),
            Failure::Refused {
                status,
                code,
                message,
                url,
            } => Error::Invalid(format!(
                "the MLflow server refused {url} (HTTP {status}{}): {message}",
                if code.is_empty() {
                    String::new()
                } else {
                    format!(", {code}")
                },
            )),
        }
    }
}

/// `name` as MLflow accepts it: letters, digits and `_ - . / : space` kept,
/// anything else `_`.
pub fn key(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || "_-./: ".contains(c) {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// What an export did with one replicate.
pub enum Outcome {
    /// Exported now, as this MLflow run, with so many parameters, metric
    /// values and artifacts.
    Exported {
        run_id: String,
        params: usize,
        metrics: usize,
        artifacts: usize,
    },
    /// Already exported, as this MLflow run.
    AlreadyThere { run_id: String },
}

/// Exports every variant and replicate of `record` to the server, under the
/// MLflow experiment `experiment`; `report` is the folder of the report
/// rendered from the record (its files become artifacts) if there is one.
/// Calls `done` with each variant record and what became of it.
pub fn export(
    client: &Client,
    record: &RunRecord,
    experiment: &str,
    report: Option<&Path>,
    mut done: impl FnMut(&VariantRecord, &Outcome),
) -> Result<()> {
    let experiment_id = experiment_id(client, experiment)?;
    let start_ms = humantime::parse_rfc3339(&record.started)
        .ok()
        .and_then(|t| t.duration_since(UNIX_EPOCH).ok())
        .map_or(0, |d| d.as_millis() as i64);
    let end_ms = start_ms + (record.wall_seconds * 1000.0) as i64;
    let record_json = serde_json::to_vec_pretty(record).expect("records serialize");
    let report_files = match report {
        Some(dir) => files_of(dir)?,
        None => Vec::new(),
    };
    for variant in &record.variants {
        let tags = [
            ("alnlab.run_id", record.id.clone()),
            ("alnlab.experiment", record.experiment.clone()),
            ("alnlab.variant", variant.name.clone()),
            ("alnlab.replicate", (variant.replicate + 1).to_string()),
            ("alnlab.seed", variant.seed.to_string()),
            ("alnlab.manifest", record.manifest_path.clone()),
            ("alnlab.manifest_sha256", record.manifest_sha256.clone()),
            ("alnlab.version", record.alnlab_version.clone()),
            (
                "mlflow.source.git.commit",
                record.git_commit.clone().unwrap_or_default(),
            ),
            ("mlflow.note.content", variant.description.clone()),
        ];
        let filter = format!(
            "tags.`alnlab.run_id` = '{}' and tags.`alnlab.variant` = '{}' and \
             tags.`alnlab.replicate` = '{}'",
            record.id,
            variant.name,
            variant.replicate + 1
        );
        let found = client.post(
            "runs/search",
            &json!({
                "experiment_ids": [experiment_id],
                "filter": filter,
                "run_view_type": "ACTIVE_ONLY",
                "max_results": 10,
            }),
        )?;
        let mut finished = None;
        for run in found["runs"].as_array().into_iter().flatten() {
            let run_id = run["info"]["run_id"]
                .as_str()
                .unwrap_or_default()
                .to_string();
            let complete = run["data"]["tags"]
                .as_array()
                .into_iter()
                .flatten()
                .any(|t| t["key"] == EXPORTED_TAG && t["value"] == "complete");
            if complete && finished.is_none() {
                finished = Some(run_id);
            } else {
                // An export cut short, or a duplicate: made again below.
                client.post("runs/delete", &json!({ "run_id": run_id }))?;
            }
        }
        if let Some(run_id) = finished {
            done(variant, &Outcome::AlreadyThere { run_id });
            continue;
        }
        // Unique in the experiment: the variant, its replicate, the run.
        let run_name = if record.variants.iter().any(|v| v.replicate > 0) {
            format!(
                "{} #{} ({})",
                variant.name,
                variant.replicate + 1,
                record.id
            )
        } else {
            format!("{} ({})", variant.name, record.id)
        };
        let created = client.post(
            "runs/create",
            &json!({
                "experiment_id": experiment_id,
                "run_name": run_name,
                "start_time": start_ms,
                "tags": tags.iter().map(|(k, v)| json!({"key": k, "value": v})).collect::<Vec<_>>(),
            }),
        )?;
        let info = &created["run"]["info"];
        let run_id = info["run_id"]
            .as_str()
            .ok_or_else(|| Error::Invalid(format!("{}: runs/create gave no run id", client.base)))?
            .to_string();
        let params = log_params(client, &run_id, variant)?;
        let metrics = log_metrics(client, &run_id, variant, start_ms)?;
        let mut artifacts = 0;
        match proxied_path(info["artifact_uri"].as_str().unwrap_or("")) {
            Some(root) => {
                client.put(&format!("{root}/run.json"), &record_json)?;
                artifacts += 1;
                for (name, bytes) in &report_files {
                    client.put(&format!("{root}/report/{name}"), bytes)?;
                    artifacts += 1;
                }
            }
            None => eprintln!(
                "warning: MLflow run {run_id}: artifacts not uploaded — its artifact store ({}) \
                 is not served by the tracking server (start it with --serve-artifacts)",
                info["artifact_uri"]
            ),
        }
        client.post(
            "runs/update",
            &json!({ "run_id": run_id, "status": "FINISHED", "end_time": end_ms }),
        )?;
        client.post(
            "runs/set-tag",
            &json!({ "run_id": run_id, "key": EXPORTED_TAG, "value": "complete" }),
        )?;
        done(
            variant,
            &Outcome::Exported {
                run_id,
                params,
                metrics,
                artifacts,
            },
        );
    }
    Ok(())
}

/// The id of the MLflow experiment `name`, created if there is none.
fn experiment_id(client: &Client, name: &str) -> Result<String> {
    let found = client.get("experiments/get-by-name", &[("experiment_name", name)]);
    let experiment = match found {
        Ok(answer) => answer["experiment"].clone(),
        Err(Failure::Refused { code, .. }) if code == "RESOURCE_DOES_NOT_EXIST" => {
            // Tagged as model training, so MLflow's UI opens on its runs.
            let made = client.post(
                "experiments/create",
                &json!({
                    "name": name,
                    "tags": [{ "key": "mlflow.experimentKind", "value": "custom_model_development" }],
                }),
            )?;
            return made["experiment_id"]
                .as_str()
                .map(str::to_string)
                .ok_or_else(|| {
                    Error::Invalid(format!("{}: experiments/create gave no id", client.base))
                });
        }
        Err(e) => return Err(e.into()),
    };
    if experiment["lifecycle_stage"] == "deleted" {
        return Err(Error::Invalid(format!(
            "the MLflow experiment `{name}` is deleted; restore it (`mlflow experiments restore \
             --experiment-id {}`) or export under another name with --experiment",
            experiment["experiment_id"].as_str().unwrap_or("?")
        )));
    }
    experiment["experiment_id"]
        .as_str()
        .map(str::to_string)
        .ok_or_else(|| Error::Invalid(format!("{}: experiment `{name}` has no id", client.base)))
}

/// Logs the variant's parameters; returns how many.
fn log_params(client: &Client, run_id: &str, variant: &VariantRecord) -> Result<usize> {
    let params: Vec<Value> = variant
        .parameters
        .iter()
        .map(|(k, v)| {
            if v.len() > MAX_PARAM_VALUE {
                return Err(Error::Invalid(format!(
                    "parameter {k} of variant `{}` is {} characters long; MLflow takes at most \
                     {MAX_PARAM_VALUE}",
                    variant.name,
                    v.len()
                )));
            }
            Ok(json!({ "key": key(k), "value": v }))
        })
        .collect::<Result<_>>()?;
    for chunk in params.chunks(PARAMS_PER_BATCH) {
        client.post(
            "runs/log-batch",
            &json!({ "run_id": run_id, "params": chunk }),
        )?;
    }
    Ok(params.len())
}

/// Logs the variant's metrics (figures at step 0, series by step); returns
/// how many values.
fn log_metrics(
    client: &Client,
    run_id: &str,
    variant: &VariantRecord,
    timestamp: i64,
) -> Result<usize> {
    let Some(metrics) = &variant.metrics else {
        return Ok(0);
    };
    let point = |name: &str, value: f64, step: u32| json!({ "key": key(name), "value": value, "timestamp": timestamp, "step": step });
    let values: Vec<Value> = metrics
        .values
        .iter()
        .map(|(name, &value)| point(name, value, 0))
        .chain(metrics.steps.iter().flat_map(|(name, series)| {
            series
                .iter()
                .map(move |&(step, value)| point(name, value, step))
        }))
        .collect();
    for chunk in values.chunks(METRICS_PER_BATCH) {
        client.post(
            "runs/log-batch",
            &json!({ "run_id": run_id, "metrics": chunk }),
        )?;
    }
    Ok(values.len())
}

/// The path under `/api/2.0/mlflow-artifacts/artifacts/` of a run's
/// artifact root, when the server proxies it: `mlflow-artifacts:/1/<run>/artifacts`
/// or an http(s) address on that route. `None` for a store the client
/// would have to reach itself (a local folder, S3, …).
fn proxied_path(artifact_uri: &str) -> Option<String> {
    const ROUTE: &str = "/api/2.0/mlflow-artifacts/artifacts/";
    let path = if let Some(rest) = artifact_uri.strip_prefix("mlflow-artifacts:") {
        // `mlflow-artifacts:/path` or `mlflow-artifacts://host:port/path`.
        match rest.strip_prefix("//") {
            Some(with_host) => with_host.split_once('/').map_or("", |(_, p)| p),
            None => rest,
        }
    } else if artifact_uri.starts_with("http://") || artifact_uri.starts_with("https://") {
        artifact_uri.split_once(ROUTE)?.1
    } else {
        return None;
    };
    let path = path.trim_matches('/');
    (!path.is_empty()).then(|| path.to_string())
}

/// The files of a report folder (not recursive: the report's Markdown,
/// HTML and charts), by name, sorted.
fn files_of(dir: &Path) -> Result<Vec<(String, Vec<u8>)>> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let path = entry.map_err(|e| Error::io(dir, e))?.path();
        if path.is_file() {
            let name = path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let bytes = std::fs::read(&path).map_err(|e| Error::io(&path, e))?;
            files.push((name, bytes));
        }
    }
    files.sort();
    Ok(files)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_keep_what_mlflow_accepts() {
        assert_eq!(key("error/simulator@1/frame"), "error/simulator_1/frame");
        assert_eq!(
            key("error_by_variable/aln/f_E.1.x"),
            "error_by_variable/aln/f_E.1.x"
        );
        assert_eq!(key("simulate.scene.0.dt"), "simulate.scene.0.dt");
    }

    #[test]
    fn proxied_artifact_paths() {
        assert_eq!(
            proxied_path("mlflow-artifacts:/1/abc/artifacts").as_deref(),
            Some("1/abc/artifacts")
        );
        assert_eq!(
            proxied_path("mlflow-artifacts://host:5000/1/abc/artifacts").as_deref(),
            Some("1/abc/artifacts")
        );
        assert_eq!(
            proxied_path("http://h:5000/api/2.0/mlflow-artifacts/artifacts/1/abc/artifacts")
                .as_deref(),
            Some("1/abc/artifacts")
        );
        assert_eq!(proxied_path("/var/mlruns/1/abc/artifacts"), None);
        assert_eq!(proxied_path("s3://bucket/1/abc/artifacts"), None);
    }
}

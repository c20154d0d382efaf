//! The stack's settings as the protocol's parameters, read-only: `mems-stack` passes each of
//! its settings as `--parameter NAME=VALUE`; a client's `getParameters` receives them (all,
//! or the names it asks for) and a `setParameters` is answered with the values unchanged.
//! A value is an integer, a float, `true`/`false` or else a string.

use foxglove::websocket::{
    AnyClient, GetParametersResponder, Parameter, ParameterHandler, SetParametersResponder,
};

/// The settings, in the order given.
pub struct Settings(Vec<Parameter>);

impl Settings {
    /// Parses `NAME=VALUE` pairs; errors name the pair without `=`.
    pub fn parse(pairs: &[String]) -> anyhow::Result<Self> {
        let parameters = pairs
            .iter()
            .map(|pair| {
                let (name, value) = pair
                    .split_once('=')
                    .ok_or_else(|| anyhow::anyhow!("--parameter {pair:?}: expected NAME=VALUE"))?;
                Ok(typed(name, value))
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(Self(parameters))
    }

    /// The named settings (all of them for no names).
    fn select(&self, names: &[String]) -> Vec<Parameter> {
        self.0
            .iter()
            .filter(|p| names.is_empty() || names.contains(&p.name))
            .cloned()
            .collect()
    }
}

/// The parameter `name` with `value` as the type it reads as.
fn typed(name: &str, value: &str) -> Parameter {
    if let Ok(i) = value.parse::<i64>() {
        Parameter::integer(name, i)
    } else if let Ok(x) = value.parse::<f64>() {
        Parameter::float64(name, x)
    } else if let Ok(b) = value.parse::<bool>() {
        Parameter::bool(name, b)
    } else {
        Parameter::string(name, value)
    }
}

impl ParameterHandler for Settings {
    fn get(
        &self,
        _client: AnyClient,
        names: Vec<String>,
        _request_id: Option<String>,
        responder: GetParametersResponder,
    ) {
        responder.respond(self.select(&names));
    }

    /// Read-only: answers with the current values of the parameters named.
    fn set(
        &self,
        _client: AnyClient,
        parameters: Vec<Parameter>,
        _request_id: Option<String>,
        responder: SetParametersResponder,
    ) {
        let names: Vec<String> = parameters.into_iter().map(|p| p.name).collect();
        if !names.is_empty() {
            tracing::warn!("warning: parameters are read-only; not set: {names:?}");
        }
        responder.respond(if names.is_empty() {
            Vec::new()
        } else {
            self.select(&names)
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use foxglove::websocket::ParameterValue;

    #[test]
    fn values_are_typed_and_names_selected() {
        let pairs = [
            "rate=1000",
            "duration=60.5",
            "force=true",
            "source=sim",
            "empty=",
        ]
        .map(String::from);
        let s = Settings::parse(&pairs).unwrap();
        let values: Vec<_> = s.select(&[]).into_iter().map(|p| p.value).collect();
        assert_eq!(
            values,
            [
                Some(ParameterValue::Integer(1000)),
                Some(ParameterValue::Float64(60.5)),
                Some(ParameterValue::Bool(true)),
                Some(ParameterValue::String("sim".into())),
                Some(ParameterValue::String(String::new())),
            ]
        );
        assert_eq!(s.select(&["source".into()]).len(), 1);
        assert!(Settings::parse(&["rate".into()]).is_err());
    }
}

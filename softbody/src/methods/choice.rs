//! Model no more than a scene needs: per object, the cheapest method and resolution whose
//! measured error meets the object's error budget; sleeping or untouched objects cost nothing;
//! the plan says whether the total fits the frame budget.

use serde::Serialize;

use crate::methods::spec::MethodSpec;

/// One measured point of a method's speed/accuracy curve for one object.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Candidate {
    /// The method and resolution.
    pub spec: MethodSpec,
    /// Measured cost per step (milliseconds, or any unit consistent with the frame budget).
    pub cost_ms: f32,
    /// Measured error to the reference, millimetres.
    pub error_mm: f32,
}

/// An object of the scene and what it may cost.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ObjectNeeds {
    /// Name for tables.
    pub name: String,
    /// Largest acceptable error, millimetres.
    pub error_budget_mm: f32,
    /// False if the object is asleep or nothing touches it: it is not simulated at all.
    pub active: bool,
    /// Its measured curve points.
    pub candidates: Vec<Candidate>,
}

/// What was picked for one object.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Choice {
    /// The object.
    pub object: String,
    /// The candidate, or `None` for an inactive object (costs nothing).
    pub picked: Option<Candidate>,
    /// Its cost (0 if inactive).
    pub cost_ms: f32,
    /// True if its error is within the object's budget (always for inactive objects).
    pub meets_error_budget: bool,
}

/// The plan for a scene.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Plan {
    /// One choice per object, in order.
    pub choices: Vec<Choice>,
    /// Sum of the costs.
    pub total_ms: f32,
    /// Total within the frame budget.
    pub meets_frame_budget: bool,
}

impl Plan {
    /// True if every error budget and the frame budget are met.
    pub fn meets_budgets(&self) -> bool {
        self.meets_frame_budget && self.choices.iter().all(|c| c.meets_error_budget)
    }
}

/// Picks, per active object, the cheapest candidate within its error budget (or, if none is,
/// the most accurate one, flagged); inactive objects get nothing. Non-finite measurements are
/// ignored.
pub fn choose(objects: &[ObjectNeeds], frame_budget_ms: f32) -> Plan {
    let mut choices = Vec::with_capacity(objects.len());
    for o in objects {
        if !o.active {
            choices.push(Choice {
                object: o.name.clone(),
                picked: None,
                cost_ms: 0.0,
                meets_error_budget: true,
            });
            continue;
        }
        let valid = o
            .candidates
            .iter()
            .filter(|c| c.cost_ms.is_finite() && c.error_mm.is_finite());
        let feasible = valid
            .clone()
            .filter(|c| c.error_mm <= o.error_budget_mm)
            .min_by(|a, b| a.cost_ms.total_cmp(&b.cost_ms));
        let (picked, ok) = match feasible {
            Some(c) => (Some(c.clone()), true),
            None => (
                valid
                    .min_by(|a, b| a.error_mm.total_cmp(&b.error_mm))
                    .cloned(),
                false,
            ),
        };
        choices.push(Choice {
            object: o.name.clone(),
            cost_ms: picked.as_ref().map_or(0.0, |c| c.cost_ms),
            picked,
            meets_error_budget: ok,
        });
    }
    let total_ms = choices.iter().map(|c| c.cost_ms).sum();
    Plan {
        choices,
        total_ms,
        meets_frame_budget: total_ms <= frame_budget_ms,
    }
}

/// The candidates no other candidate beats on both cost and error, cheapest first.
pub fn pareto_front(candidates: &[Candidate]) -> Vec<Candidate> {
    let mut c: Vec<Candidate> = candidates
        .iter()
        .filter(|c| c.cost_ms.is_finite() && c.error_mm.is_finite())
        .cloned()
        .collect();
    c.sort_by(|a, b| a.cost_ms.total_cmp(&b.cost_ms));
    let mut out: Vec<Candidate> = Vec::new();
    for x in c {
        if out.last().is_none_or(|l| x.error_mm < l.error_mm) {
            out.push(x);
        }
    }
    out
}

//! The model registry: the one place in the simulator that turns a vehicle of some model into a
//! generic call (`/docs/architecture.md`, "Vehicle models: the registry").
//!
//! Each model of the family implements [`ModelEntry`] (what a vehicle file, a set name and a
//! command need of it: its named sets, its file section, its fields, how its vehicle is
//! assembled) in its plant file, next to its [`SimModel`]; the `registry!` list below names
//! it once and makes from that list
//! - the enum [`ModelVehicle`] (a vehicle of any model, as a vehicle file or a set name gives
//!   it),
//! - [`with_model`]: a [`ModelVisitor`]'s generic method called with the vehicle's model as its
//!   type (the only match over the models),
//! - [`for_each_model`]: a [`ModelTypeVisitor`]'s generic method called for every model in the
//!   list's order (set names, file models, messages),
//! - [`Registered`]: a model's way into and out of [`ModelVehicle`].
//!
//! A command is written once, generic over `M: Registered<N>`, and called through
//! [`with_model`]. What only some models have is not a match: scenario files are an optional
//! constant of [`ModelEntry`] with a default; a firmware image is the model's
//! [`BoardModel`] and [`StudyModel`], marked `study` in the list, which
//! [`with_image_model`] and [`for_each_image_model`] visit.
//!
//! Adding a model: a core folder (`core/src/vehicles/<model>/`), a plant file
//! (`host-sim/src/model/<model>_plant.rs`: its [`SimPlant`](super::family::SimPlant),
//! [`SimModel`] and [`ModelEntry`], and for a model with a firmware image its [`BoardModel`]
//! and [`StudyModel`]) and a line in the list below.

use anyhow::Result;
use shimmy_core::model::LinearModel;
use shimmy_core::vehicle::{record_schema_of, Vehicle, SECTIONS};
use shimmy_core::vehicles::{FieldError, ModelField};

use super::board::BoardModel;
use super::family::SimModel;
use super::study::StudyModel;

/// What the simulator's commands and files need of a vehicle model beyond its [`SimModel`]:
/// implemented by each model in its plant file.
pub trait ModelEntry<const N: usize>: SimModel<N> {
    /// A vehicle of this model as a vehicle file or a set name gives it (the car: the core's
    /// whole `Vehicle`; another model: its parameters and, where its files have them, the
    /// shared sections).
    type File: Clone + std::fmt::Debug + PartialEq + Send + Sync + 'static;

    /// The section of a vehicle file with the model's parameters (`truck`, ...); `None`: the
    /// model's files are whole core vehicle files (the car: `[plant]` and the shared
    /// sections).
    const SECTION: Option<&'static str>;
    /// Whether the model's files take the shared sections (`[damper]`, `[damper_model]`,
    /// `[sensors]`, `[controller]`, `[thresholds]`) besides its own.
    const SHARED_SECTIONS: bool;
    /// The set a file's `base` defaults to.
    const DEFAULT_SET: &'static str;
    /// Whether the model's vehicles have an MR damper configured (the trailer's has none:
    /// `sway-damping` sizes one).
    const MR_DAMPER: bool = true;
    /// Whether scenario files take the model's vehicles (the dual-axle truck's not so far).
    const SCENARIOS: bool = true;
    /// Why a scenario's `[driver]` section is refused for the model, after its name (`None`:
    /// a driver's torque reaches its steering).
    const NO_DRIVER: Option<&'static str> = None;
    /// The fields of [`Self::fields`] the sensitivity study leaves out (those that do not enter
    /// the linear model without a damper).
    const NO_LINEAR_EFFECT: &'static [&'static str] = &[];

    /// The named sets, in their documentation's order.
    fn set_names() -> Vec<&'static str>;
    /// The parameters of the set `name`, if it is one of this model's.
    fn set(name: &str) -> Option<Self>;
    /// The vehicle of the set `name` (its parameters and the model's shared sections).
    fn named(name: &str) -> Option<Result<Self::File>> {
        Self::set(name).map(|m| Self::assemble(m, None))
    }
    /// The vehicle of the parameters `model` with the shared sections `parts` (a file's), or
    /// the model's own when `None`.
    fn assemble(model: Self, parts: Option<Vehicle>) -> Result<Self::File>;

    /// The fields of the model's section, by name (empty for the car, whose parameters are
    /// the core vehicle's `[plant]` section).
    fn fields() -> &'static [ModelField];
    /// The value of the field `name` of the model's section.
    fn field(&self, name: &str) -> Option<f64>;
    /// Sets the field `name` of the model's section.
    fn set_field(&mut self, name: &str, value: f64) -> Result<(), FieldError>;
    /// The parameters as a whole, the message naming the field.
    fn check(&self) -> Result<(), String>;
    /// [`Self::check`] as a vehicle file reports it (the field named inside the section).
    fn check_in_file(&self) -> Result<()> {
        self.check().map_err(|e| anyhow::anyhow!("{e}"))
    }

    /// The model's parameters of `f`.
    fn model_of(f: &Self::File) -> Self;
    /// The model's parameters of `f`, to set.
    fn model_mut(f: &mut Self::File) -> &mut Self;
    /// The shared sections of `f`, if its files have them.
    fn parts_of(f: &Self::File) -> Option<&Vehicle>;
    /// The shared sections of `f`, to set, if its files have them.
    fn parts_of_mut(f: &mut Self::File) -> Option<&mut Vehicle>;
    /// The vehicle as the simulator runs it (with the shared sections the model's own when its
    /// files have none).
    fn vehicle(f: Self::File) -> Result<Self::Vehicle>;
    /// The vehicle `v` as its files give it (the inverse of [`Self::vehicle`]).
    fn file_of(v: &Self::Vehicle) -> Self::File;
    /// `v` with the model's parameters replaced by `model` (the shared sections stay).
    fn with_params(v: &Self::Vehicle, model: Self) -> Self::Vehicle;
}

/// A model of the `registry!` list: its [`ModelEntry`] and its variant of [`ModelVehicle`]
/// (implemented by the list).
pub trait Registered<const N: usize>: ModelEntry<N> {
    /// `f` as a vehicle of any model.
    fn into_any(f: Self::File) -> ModelVehicle;
    /// The vehicle of this model in `v`, or `v` when it is of another.
    #[allow(clippy::result_large_err)] // read once per command
    fn from_any(v: ModelVehicle) -> std::result::Result<Self::File, ModelVehicle>;
}

/// A generic call on a vehicle of some model: [`with_model`] calls [`Self::visit`] with the
/// vehicle's model as `M`.
pub trait ModelVisitor {
    /// What the call gives.
    type Output;
    /// The call on the vehicle `v` of the model `M`.
    fn visit<M: Registered<N>, const N: usize>(self, v: M::File) -> Self::Output;
}

/// A generic call on a model, not a vehicle: [`for_each_model`] calls [`Self::visit`] with
/// every model of the list as `M`.
pub trait ModelTypeVisitor {
    /// The call on the model `M`.
    fn visit<M: Registered<N>, const N: usize>(&mut self);
}

/// The sections of a vehicle file shared by every model that `M`'s files take (the car's:
/// all, `[plant]` included).
pub fn shared_sections<M: ModelEntry<N>, const N: usize>() -> &'static [&'static str] {
    match (M::SECTION, M::SHARED_SECTIONS) {
        (None, _) => &SECTIONS,
        (Some(_), true) => &SECTIONS[1..],
        (Some(_), false) => &[],
    }
}

/// `M`'s set names, comma separated (messages).
pub fn set_names_of<M: ModelEntry<N>, const N: usize>() -> String {
    M::set_names().join(", ")
}

/// The name of the model `M` (`car-4dof`, ...).
pub fn name_of<M: ModelEntry<N>, const N: usize>() -> &'static str {
    <M::Linear as LinearModel<N>>::NAME
}

/// The list of the models: the enum, the dispatch and the way in and out of the enum.
macro_rules! registry {
    ($( $(#[$doc:meta])* $variant:ident => $model:ty, $n:expr, [$($cap:ident)?]; )*) => {
        /// A vehicle of any model of the family, as a vehicle file or a set name gives it (read
        /// once per command: the size difference of the variants does not matter).
        #[derive(Clone, Debug, PartialEq)]
        #[allow(clippy::large_enum_variant)]
        pub enum ModelVehicle {
            $( $(#[$doc])* $variant(<$model as ModelEntry<{ $n }>>::File), )*
        }

        impl ModelVehicle {
            /// The model's name (`car-4dof`, `mining-truck-5dof`, ...).
            pub fn model_name(&self) -> &'static str {
                match self {
                    $( ModelVehicle::$variant(_) => name_of::<$model, { $n }>(), )*
                }
            }
        }

        /// Calls `visitor` on `v` with `v`'s model as its type.
        pub fn with_model<V: ModelVisitor>(v: ModelVehicle, visitor: V) -> V::Output {
            match v {
                $( ModelVehicle::$variant(f) => visitor.visit::<$model, { $n }>(f), )*
            }
        }

        /// Calls `visitor` on `v` with `v`'s model as its type if that is a model with a
        /// firmware image ([`StudyModel`]: marked `study` in the list), else gives `v` back.
        #[allow(clippy::result_large_err)] // read once per command
        pub fn with_image_model<V: StudyVisitor>(
            v: ModelVehicle,
            visitor: V,
        ) -> std::result::Result<V::Output, ModelVehicle> {
            match v {
                $( ModelVehicle::$variant(f) => <$model as MaybeStudy<{ $n }>>::study(f, visitor)
                    .map_err(ModelVehicle::$variant), )*
            }
        }

        $( maybe_study!($model, $n, $($cap)?); )*

        /// The names of the models with a firmware image (the study models), in the list's
        /// order.
        pub fn image_model_names() -> Vec<&'static str> {
            let mut names = Vec::new();
            $(
                if <$model as MaybeStudy<{ $n }>>::STUDY {
                    names.push(name_of::<$model, { $n }>());
                }
            )*
            names
        }

        /// Calls `visitor` for every model with a firmware image, in the list's order.
        pub fn for_each_image_model<V: StudyTypeVisitor>(visitor: &mut V) {
            $( <$model as MaybeStudy<{ $n }>>::visit_type(visitor); )*
        }

        /// Calls `visitor` for every model, in the list's order.
        pub fn for_each_model<V: ModelTypeVisitor>(visitor: &mut V) {
            $( visitor.visit::<$model, { $n }>(); )*
        }

        $(
            impl Registered<{ $n }> for $model {
                fn into_any(f: Self::File) -> ModelVehicle {
                    ModelVehicle::$variant(f)
                }
                #[allow(clippy::result_large_err)]
                fn from_any(v: ModelVehicle) -> std::result::Result<Self::File, ModelVehicle> {
                    match v {
                        ModelVehicle::$variant(f) => Ok(f),
                        #[allow(unreachable_patterns)]
                        other => Err(other),
                    }
                }
            }
        )*
    };
}

/// A model's [`StudyVisitor`] call if it is a study model (`study` in the list).
trait MaybeStudy<const N: usize>: ModelEntry<N> {
    /// Whether the model is a study model.
    const STUDY: bool;
    /// Calls `visitor` with the model if it is a study model.
    fn visit_type<V: StudyTypeVisitor>(visitor: &mut V);
    #[allow(clippy::result_large_err)]
    fn study<V: StudyVisitor>(
        f: Self::File,
        visitor: V,
    ) -> std::result::Result<V::Output, Self::File>;
}

/// The [`MaybeStudy`] of a list line: with `study`, the call; without, the vehicle back.
macro_rules! maybe_study {
    ($model:ty, $n:expr, study) => {
        impl MaybeStudy<{ $n }> for $model {
            const STUDY: bool = true;
            fn visit_type<V: StudyTypeVisitor>(visitor: &mut V) {
                visitor.visit::<Self, { $n }>();
            }
            #[allow(clippy::result_large_err)]
            fn study<V: StudyVisitor>(
                f: Self::File,
                visitor: V,
            ) -> std::result::Result<V::Output, Self::File> {
                Ok(visitor.visit::<Self, { $n }>(f))
            }
        }
    };
    ($model:ty, $n:expr,) => {
        impl MaybeStudy<{ $n }> for $model {
            const STUDY: bool = false;
            fn visit_type<V: StudyTypeVisitor>(_: &mut V) {}
            #[allow(clippy::result_large_err)]
            fn study<V: StudyVisitor>(
                f: Self::File,
                _: V,
            ) -> std::result::Result<V::Output, Self::File> {
                Err(f)
            }
        }
    };
}

/// A generic call on a vehicle of a model with a firmware image (the studies' models,
/// [`StudyModel`]): [`with_image_model`] calls [`Self::visit`] with the vehicle's model as `M`.
pub trait StudyVisitor {
    /// What the call gives.
    type Output;
    /// The call on the vehicle `v` of the model `M`.
    fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(self, v: M::File) -> Self::Output;
}

/// A generic call on a model with a firmware image, not a vehicle: [`for_each_image_model`]
/// calls [`Self::visit`] with every such model as `M`.
pub trait StudyTypeVisitor {
    /// The call on the model `M`.
    fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self);
}

// The models' list: `Variant => parameter type, state count, [study]` (`study`: a model with a
// firmware image, which the studies of `StudyModel` run on).
registry! {
    /// The 4-DOF car (`car-4dof`): the whole vehicle (plant, damper, sensors, gains).
    Car => shimmy_core::vehicles::car::PlantParams, shimmy_core::vehicles::car::N_STATES, [study];
    /// The mining dump truck (`mining-truck-5dof`): its model's parameters, damper, sensors,
    /// gains and thresholds.
    Truck => shimmy_core::vehicles::truck::TruckParams, shimmy_core::vehicles::truck::N_STATES, [study];
    /// The dual-front-axle heavy truck (`dual-axle-truck-8dof`): its model's parameters and the
    /// shared sections (the car's reference damper, sensors and gains, unsized for it).
    DualAxle => shimmy_core::vehicles::dual_axle::DualAxleParams, shimmy_core::vehicles::dual_axle::N_STATES, [];
    /// The trailer on a compliant hitch (`trailer-2dof`): its linear model's parameters.
    Trailer => shimmy_core::vehicles::trailer::TrailerParams, shimmy_core::vehicles::trailer::N_STATES, [];
    /// The towed wheel on a stretched-string tyre (`towed-wheel-string`): the public shimmy
    /// benchmark of Takács, Orosz & Stépán (2009).
    TowedWheel => shimmy_core::vehicles::towed_wheel::TowedWheelParams, shimmy_core::vehicles::towed_wheel::N_STATES, [];
}

/// The reference model: the car (`car-4dof`). The default of the simulator's generic types
/// (`LoopConfig`, `ScenarioSpec`, `DemoCase`, ...) and of a vehicle file without a `model` key,
/// and the vehicle the other models' dampers and road disturbances are sized against.
pub type ReferenceModel = shimmy_core::vehicles::car::PlantParams;
/// The reference model's state count.
pub const REFERENCE_N: usize = shimmy_core::vehicles::car::N_STATES;

/// The names of the models, in the list's order.
pub fn model_names() -> Vec<&'static str> {
    struct Names(Vec<&'static str>);
    impl ModelTypeVisitor for Names {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            self.0.push(name_of::<M, N>());
        }
    }
    let mut n = Names(Vec::new());
    for_each_model(&mut n);
    n.0
}

/// The vehicle of the set name `spec` of any model, if it is one.
pub fn named_vehicle(spec: &str) -> Option<Result<ModelVehicle>> {
    struct Find<'a>(&'a str, Option<Result<ModelVehicle>>);
    impl ModelTypeVisitor for Find<'_> {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            if self.1.is_none() {
                self.1 = M::named(self.0).map(|r| r.map(M::into_any));
            }
        }
    }
    let mut f = Find(spec, None);
    for_each_model(&mut f);
    f.1
}

/// Every named set of every model (the shipped vehicles), in the list's order.
pub fn all_sets() -> Vec<&'static str> {
    struct Names(Vec<&'static str>);
    impl ModelTypeVisitor for Names {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            self.0.extend(M::set_names());
        }
    }
    let mut n = Names(Vec::new());
    for_each_model(&mut n);
    n.0
}

/// The set names of every model, each model's comma separated, the models' joined by `sep`.
pub fn all_set_names(sep: &str) -> String {
    struct Names(Vec<String>);
    impl ModelTypeVisitor for Names {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            self.0.push(set_names_of::<M, N>());
        }
    }
    let mut n = Names(Vec::new());
    for_each_model(&mut n);
    n.0.join(sep)
}

/// The name of the model whose named set `spec` is, if it is one.
pub fn model_of_set(spec: &str) -> Option<&'static str> {
    struct Find<'a>(&'a str, Option<&'static str>);
    impl ModelTypeVisitor for Find<'_> {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            if self.1.is_none() && M::set(self.0).is_some() {
                self.1 = Some(name_of::<M, N>());
            }
        }
    }
    let mut f = Find(spec, None);
    for_each_model(&mut f);
    f.1
}

impl From<Vehicle> for ModelVehicle {
    /// A core vehicle (a whole vehicle file's) is the car's.
    fn from(v: Vehicle) -> Self {
        ModelVehicle::Car(v)
    }
}

/// The vehicle `f` of the model `M` as the simulator runs it, as its parameters and the shared
/// sections ([`ModelEntry::vehicle`], then [`SimModel::family_vehicle`]).
pub fn family<M: ModelEntry<N>, const N: usize>(
    f: M::File,
) -> Result<super::family::FamilyVehicle<M>> {
    Ok(M::family_vehicle(&M::vehicle(f)?))
}

impl ModelVehicle {
    /// The section of the model's own parameters in its files (`None`: the car's, whose
    /// parameters are the core vehicle's `[plant]`).
    pub fn section(&self) -> Option<&'static str> {
        struct Section;
        impl ModelVisitor for Section {
            type Output = Option<&'static str>;
            fn visit<M: Registered<N>, const N: usize>(self, _: M::File) -> Self::Output {
                M::SECTION
            }
        }
        with_model(self.clone(), Section)
    }

    /// The shared sections the model's files take ([`shared_sections`]).
    pub fn shared_sections(&self) -> &'static [&'static str] {
        struct Shared;
        impl ModelVisitor for Shared {
            type Output = &'static [&'static str];
            fn visit<M: Registered<N>, const N: usize>(self, _: M::File) -> Self::Output {
                shared_sections::<M, N>()
            }
        }
        with_model(self.clone(), Shared)
    }

    /// The shared sections (damper, sensors, gains, thresholds) of the vehicle, if its model's
    /// files have them (the car: the whole vehicle).
    pub fn parts(&self) -> Option<Vehicle> {
        struct Parts;
        impl ModelVisitor for Parts {
            type Output = Option<Vehicle>;
            fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
                M::parts_of(&f).copied()
            }
        }
        with_model(self.clone(), Parts)
    }

    /// The fields of the model's own section ([`ModelEntry::fields`]; none for the car).
    pub fn model_fields(&self) -> &'static [ModelField] {
        struct Fields;
        impl ModelVisitor for Fields {
            type Output = &'static [ModelField];
            fn visit<M: Registered<N>, const N: usize>(self, _: M::File) -> Self::Output {
                M::fields()
            }
        }
        with_model(self.clone(), Fields)
    }

    /// The value of the field `name` of the model's own section.
    pub fn model_field(&self, name: &str) -> Option<f64> {
        struct Get<'a>(&'a str);
        impl ModelVisitor for Get<'_> {
            type Output = Option<f64>;
            fn visit<M: Registered<N>, const N: usize>(self, f: M::File) -> Self::Output {
                M::model_of(&f).field(self.0)
            }
        }
        with_model(self.clone(), Get(name))
    }

    /// The vehicle with the field `name` of the model's own section set to `value`: the
    /// field's error ([`ModelEntry::set_field`]), or the whole checked as a vehicle file
    /// checks it ([`ModelEntry::check_in_file`]) in the inner result.
    pub fn with_model_field(
        &self,
        name: &str,
        value: f64,
    ) -> std::result::Result<Result<ModelVehicle>, FieldError> {
        struct Set<'a>(&'a str, f64);
        impl ModelVisitor for Set<'_> {
            type Output = std::result::Result<Result<ModelVehicle>, FieldError>;
            fn visit<M: Registered<N>, const N: usize>(self, mut f: M::File) -> Self::Output {
                let mut t = M::model_of(&f);
                t.set_field(self.0, self.1)?;
                Ok(t.check_in_file().map(|()| {
                    *M::model_mut(&mut f) = t;
                    M::into_any(f)
                }))
            }
        }
        with_model(self.clone(), Set(name, value))
    }

    /// The vehicle with its shared sections replaced by `parts`, if its model's files have
    /// them.
    pub fn with_parts(&self, parts: Vehicle) -> Option<ModelVehicle> {
        struct Put(Vehicle);
        impl ModelVisitor for Put {
            type Output = Option<ModelVehicle>;
            fn visit<M: Registered<N>, const N: usize>(self, mut f: M::File) -> Self::Output {
                *M::parts_of_mut(&mut f)? = self.0;
                Some(M::into_any(f))
            }
        }
        with_model(self.clone(), Put(parts))
    }
}

/// The models whose vehicles have an MR damper configured ([`ModelEntry::MR_DAMPER`]), in the
/// list's order.
pub fn damped_models() -> Vec<&'static str> {
    struct Damped(Vec<&'static str>);
    impl ModelTypeVisitor for Damped {
        fn visit<M: Registered<N>, const N: usize>(&mut self) {
            if M::MR_DAMPER {
                self.0.push(name_of::<M, N>());
            }
        }
    }
    let mut d = Damped(Vec::new());
    for_each_model(&mut d);
    d.0
}

/// `a`, `a and b`, `a, b and c`: names for messages.
pub fn and_list(names: &[&str]) -> String {
    match names {
        [] => String::new(),
        [one] => (*one).to_string(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

/// The models a firmware image is built for (the study models: `car-4dof and
/// mining-truck-5dof`), for messages.
pub fn image_models() -> String {
    and_list(&image_model_names())
}

/// The name of the model whose firmware image stores records of the schema id `schema`.
pub fn image_model_of_schema(schema: u32) -> Option<&'static str> {
    struct Find(u32, Option<&'static str>);
    impl StudyTypeVisitor for Find {
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self) {
            if record_schema_of::<<M as BoardModel<N>>::Board>() == self.0 {
                self.1 = Some(name_of::<M, N>());
            }
        }
    }
    let mut f = Find(schema, None);
    for_each_image_model(&mut f);
    f.1
}

/// [`image_model_of_schema`] for messages: `unknown (schema ...)` when no image stores it.
pub fn schema_model(schema: u32) -> String {
    image_model_of_schema(schema).map_or_else(
        || format!("unknown (schema {schema:#010x})"),
        str::to_string,
    )
}

/// Where `cargo xtask pil` puts each model's image (`the car-4dof's as target/...`), for
/// messages.
pub fn image_elfs() -> String {
    struct Elfs(Vec<String>);
    impl StudyTypeVisitor for Elfs {
        fn visit<M: Registered<N> + StudyModel<N>, const N: usize>(&mut self) {
            self.0
                .push(format!("the {}'s as {}", name_of::<M, N>(), M::PIL_ELF));
        }
    }
    let mut e = Elfs(Vec::new());
    for_each_image_model(&mut e);
    let names: Vec<&str> = e.0.iter().map(String::as_str).collect();
    and_list(&names)
}

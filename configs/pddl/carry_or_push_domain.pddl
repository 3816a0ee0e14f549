; Carry-or-push (scene=carry_or_push): the cube resting on top of an upright stick must end up
; in an open box on the floor. The robot can carry it (grasp it off the stick top, place it into
; the box) or push the stick over towards the box so that the cube falls in.
; Mapping convention (realize/tasks/pddl.py): arguments of type `region` (and its subtypes) are
; the template's symbolic parameters, mapped by name to the task's params; the first `item`
; named like a scene object is the object the action handles (push: the stick it pushes, listed
; before the cube that moves); the rest (where the base parks, where the cube is) is
; bookkeeping and is dropped.
; A `site` is where the base parks, a `spot` where the cube can be; `reach` says which spots the
; arm reaches from which site. `road` is a static one-way drive graph from the start, so no plan
; loops and the planner's top-k list holds exactly the problem's skeletons.
(define (domain carry-or-push)
  (:requirements :strips :typing)
  (:types
    region site spot item - object
    base_region grasp_region place_region push_region - region)
  (:predicates
    (robot-at ?s - site)
    (road ?from - site ?to - site)
    (base-near ?r - base_region ?s - site)
    (reach ?s - site ?p - spot)
    (hand-empty)
    (holding ?c - item)
    (item-at ?c - item ?p - spot)
    (grasps ?g - grasp_region ?p - spot)
    (place-on ?r - place_region ?p - spot)
    ; pushing ?o at a point of ?r from site ?b moves what rests at ?p1 to ?p2
    (pushes ?r - push_region ?o - item ?b - site ?p1 - spot ?p2 - spot))

  (:action move_to
    :parameters (?r - base_region ?from - site ?to - site)
    :precondition (and (robot-at ?from) (road ?from ?to) (base-near ?r ?to))
    :effect (and (not (robot-at ?from)) (robot-at ?to)))

  (:action grasp
    :parameters (?g - grasp_region ?c - item ?s - site ?p - spot)
    :precondition (and (hand-empty) (robot-at ?s) (reach ?s ?p) (item-at ?c ?p) (grasps ?g ?p))
    :effect (and (not (hand-empty)) (not (item-at ?c ?p)) (holding ?c)))

  (:action place
    :parameters (?r - place_region ?c - item ?s - site ?p - spot)
    :precondition (and (holding ?c) (robot-at ?s) (reach ?s ?p) (place-on ?r ?p))
    :effect (and (not (holding ?c)) (hand-empty) (item-at ?c ?p)))

  (:action push
    :parameters (?r - push_region ?o - item ?c - item ?b - site ?p1 - spot ?p2 - spot)
    :precondition (and (hand-empty) (robot-at ?b) (item-at ?c ?p1) (pushes ?r ?o ?b ?p1 ?p2))
    :effect (and (not (item-at ?c ?p1)) (item-at ?c ?p2))))

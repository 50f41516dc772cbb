# The teahouse reception language: what the owner writes on the left, the Drools text on the right.
# Each line: [condition] or [consequence], then the phrase = what it stands for.
# {name} is filled in from the rule; {name:\d+} accepts digits only.
# A line that starts with "- " adds a constraint to the fact described on the line above.
# Longer phrases come before shorter ones that start the same way: the first match wins.

# --- Customers and their type -------------------------------------------------------------
[condition][]There is a customer without a type=$c: Customer(category == null)
[condition][]- aged between {min:\d+} and {max:\d+}=age >= {min}, age <= {max}
[condition][]- aged {min:\d+} or over=age >= {min}
[condition][]- whose age could not be estimated=age < 0
[consequence][]The customer is a "{category}"=modify($c) \{ setCategory("{category}") \};
[consequence][]The customer is an "{category}"=modify($c) \{ setCategory("{category}") \};

# --- The party at the entrance and its group ---------------------------------------------
[condition][]There is a party at the entrance=$e: Entrance()
[condition][]- of exactly {n:\d+} customers=number_of_customers == {n}
[condition][]- of exactly {n:\d+} customer=number_of_customers == {n}
[condition][]- of at least {n:\d+} customers=number_of_customers >= {n}
[condition][]- of between {min:\d+} and {max:\d+} customers=number_of_customers >= {min}, number_of_customers <= {max}
[condition][]Everyone in the party has a type=not Customer(entrance == $e.id, category == null)
[condition][]The party has no group yet=not Group(entrance == $e.id)
[condition][]Everyone in the party is a "{c1}" or an "{c2}"=exists Customer(entrance == $e.id) not Customer(entrance == $e.id, category != "{c1}", category != "{c2}")
[condition][]Everyone in the party is a "{category}"=exists Customer(entrance == $e.id) not Customer(entrance == $e.id, category != "{category}")
[condition][]Everyone in the party is an "{category}"=exists Customer(entrance == $e.id) not Customer(entrance == $e.id, category != "{category}")
[condition][]Someone in the party is a "{category}"=exists Customer(entrance == $e.id, category == "{category}")
[condition][]Someone in the party is an "{category}"=exists Customer(entrance == $e.id, category == "{category}")
[condition][]The party includes a man and a woman=exists Customer(entrance == $e.id, gender == "male") exists Customer(entrance == $e.id, gender == "female")
[consequence][]The party is a "{kind}"=insert(new Group($e.getId(), "{kind}", $e.getNumber_of_customers(), false));
[consequence][]The party is an "{kind}"=insert(new Group($e.getId(), "{kind}", $e.getNumber_of_customers(), false));

# --- Greeting the party: what Pepper says and does ---------------------------------------
[condition][]The party is a "{kind}" waiting to be greeted=$g: Group(entrance == $e.id, kind == "{kind}", greeted == false)
[condition][]The party is an "{kind}" waiting to be greeted=$g: Group(entrance == $e.id, kind == "{kind}", greeted == false)
[condition][]The party is waiting to be greeted=$g: Group(entrance == $e.id, greeted == false)
[condition][]Pepper is at the entrance=$pepper: Robot(id == "pepper", position == $e.id)
[condition][]Pepper is not at the entrance=$pepper: Robot(id == "pepper", position != $e.id)
[consequence][]Pepper says "{text}"=actions.say("pepper", "{text}");
[consequence][]Pepper gestures "{name}"=actions.gesture("pepper", "{name}");
[consequence][]Pepper comes to the entrance=actions.move("pepper", $e.getId()); modify($pepper) \{ setPosition($e.getId()) \};
[consequence][]Pepper moves to the {location}=actions.move("pepper", "{location}"); modify($pepper) \{ setPosition("{location}") \};
[consequence][]The staff are asked to "{task}"=actions.call("notify_staff", java.util.Map.of("entrance", $e.getId(), "task", "{task}"));
[consequence][]The party has been greeted=modify($g) \{ setGreeted(true) \};
